#include "png_image.hpp"

#include <png.h>

#include <csetjmp>
#include <cstdio>

#include "ivol/error.hpp"
#include "staged_file.hpp"

namespace ivol::cli {

void RgbImage::set(std::uint32_t x, std::uint32_t y, std::uint8_t r, std::uint8_t g, std::uint8_t b) {
  std::uint8_t* p = &pixels[(std::size_t{y} * width + x) * 3];
  p[0] = r, p[1] = g, p[2] = b;
}

void write_png(const RgbImage& image, const std::string& path) {
  convert::StagedFile staged(path);
  FILE* out = std::fopen(staged.temp_path().c_str(), "wb");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!out || !png || !info || setjmp(png_jmpbuf(png))) {
    if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
    if (out) std::fclose(out);
    throw Error(ErrorClass::Io, path + ": cannot write the PNG image");
  }
  png_init_io(png, out);
  png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (std::uint32_t y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(&image.pixels[std::size_t{y} * image.width * 3]));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fclose(out) != 0) throw Error(ErrorClass::Io, path + ": cannot finish the PNG image");
  staged.commit();
}

}  // namespace ivol::cli
