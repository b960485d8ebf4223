#include "png_image.hpp"

#include <png.h>
#include <unistd.h>

#include <csetjmp>
#include <cstdio>

#include "ivol/error.hpp"

namespace ivol::cli {

void RgbImage::set(std::uint32_t x, std::uint32_t y, std::uint8_t r, std::uint8_t g, std::uint8_t b) {
  std::uint8_t* p = &pixels[(std::size_t{y} * width + x) * 3];
  p[0] = r, p[1] = g, p[2] = b;
}

void write_png(const RgbImage& image, const std::string& path) {
  const auto slash = path.find_last_of('/');
  std::string temp = (slash == std::string::npos ? std::string(".") : path.substr(0, slash)) + "/.ivol-tmp-XXXXXX";
  const int fd = mkstemp(temp.data());
  if (fd < 0) throw Error(ErrorClass::Io, path + ": cannot create a temporary file");
  FILE* out = fdopen(fd, "wb");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!out || !png || !info || setjmp(png_jmpbuf(png))) {
    if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
    if (out) std::fclose(out);
    ::unlink(temp.c_str());
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
  if (std::fclose(out) != 0 || ::rename(temp.c_str(), path.c_str()) != 0) {
    ::unlink(temp.c_str());
    throw Error(ErrorClass::Io, path + ": cannot finish the PNG image");
  }
}

}  // namespace ivol::cli
