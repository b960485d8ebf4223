// 8-bit RGB images written as PNG (libpng), for slices.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace ivol::cli {

struct RgbImage {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<std::uint8_t> pixels;  // rows top to bottom, RGB
  void set(std::uint32_t x, std::uint32_t y, std::uint8_t r, std::uint8_t g, std::uint8_t b);
};

// Through a temporary file renamed when complete.
void write_png(const RgbImage& image, const std::string& path);

}  // namespace ivol::cli
