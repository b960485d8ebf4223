#include "tiff_io.hpp"

#include <tiffio.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <memory>

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

struct TiffCloser {
  void operator()(TIFF* t) const { TIFFClose(t); }
};
using TiffHandle = std::unique_ptr<TIFF, TiffCloser>;

// libtiff reports through handlers; keep the last message for our errors and
// print nothing.
thread_local std::string last_tiff_message;
void remember_tiff_message(const char* module, const char* fmt, va_list args) {
  char text[512];
  std::vsnprintf(text, sizeof text, fmt, args);
  last_tiff_message = std::string(module ? module : "libtiff") + ": " + text;
}

void install_handlers() {
  static const bool once = [] {
    TIFFSetErrorHandler(remember_tiff_message);
    TIFFSetWarningHandler(nullptr);
    return true;
  }();
  (void)once;
}

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw Error(ErrorClass::InvalidArgument, where + ": " + what);
}

struct PageFormat {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  SampleType type = SampleType::UInt8;
};

PageFormat page_format(TIFF* tif, const std::string& where) {
  PageFormat f;
  std::uint16_t bits = 0, samples = 1, format = SAMPLEFORMAT_UINT;
  TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &f.width);
  TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &f.height);
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &samples);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &format);
  if (samples != 1) fail(where, std::to_string(samples) + " samples per pixel (only grey images hold a CT slice)");
  if (bits == 8 && format == SAMPLEFORMAT_UINT)
    f.type = SampleType::UInt8;
  else if (bits == 16 && format == SAMPLEFORMAT_UINT)
    f.type = SampleType::UInt16;
  else if (bits == 16 && format == SAMPLEFORMAT_INT)
    f.type = SampleType::Int16;
  else if (bits == 16 && format == SAMPLEFORMAT_IEEEFP)
    f.type = SampleType::Float16;
  else if (bits == 32 && format == SAMPLEFORMAT_IEEEFP)
    f.type = SampleType::Float32;
  else
    fail(where, std::to_string(bits) + "-bit samples of format " + std::to_string(format) +
                    " are not supported (8/16-bit integers, 16/32-bit float)");
  if (f.width == 0 || f.height == 0) fail(where, "an empty page");
  return f;
}

// Reads one page into `out` (width * height samples, rows top to bottom).
void read_page(TIFF* tif, const PageFormat& f, std::uint8_t* out, const std::string& where) {
  const std::size_t sample = sample_size(f.type);
  const std::size_t row_bytes = std::size_t{f.width} * sample;
  if (TIFFIsTiled(tif)) {
    std::uint32_t tw = 0, th = 0;
    TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw);
    TIFFGetField(tif, TIFFTAG_TILELENGTH, &th);
    std::vector<std::uint8_t> tile(static_cast<std::size_t>(TIFFTileSize(tif)));
    for (std::uint32_t y0 = 0; y0 < f.height; y0 += th)
      for (std::uint32_t x0 = 0; x0 < f.width; x0 += tw) {
        if (TIFFReadTile(tif, tile.data(), x0, y0, 0, 0) < 0) fail(where, "cannot read a tile: " + last_tiff_message);
        const std::uint32_t w = std::min(tw, f.width - x0);
        for (std::uint32_t y = y0; y < std::min(y0 + th, f.height); ++y)
          std::memcpy(out + y * row_bytes + x0 * sample, tile.data() + (y - y0) * std::size_t{tw} * sample, w * sample);
      }
    return;
  }
  std::uint32_t rows_per_strip = f.height;
  TIFFGetFieldDefaulted(tif, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
  rows_per_strip = std::min(rows_per_strip, f.height);
  const tstrip_t strips = TIFFNumberOfStrips(tif);
  for (tstrip_t s = 0; s < strips; ++s) {
    const std::uint32_t y0 = s * rows_per_strip;
    if (y0 >= f.height) break;
    const std::uint32_t rows = std::min(rows_per_strip, f.height - y0);
    if (TIFFReadEncodedStrip(tif, s, out + y0 * row_bytes, static_cast<tmsize_t>(rows * row_bytes)) < 0)
      fail(where, "cannot read strip " + std::to_string(s) + ": " + last_tiff_message);
  }
}

TiffHandle open_tiff(const std::string& path, const char* mode) {
  install_handlers();
  TiffHandle tif(TIFFOpen(path.c_str(), mode));
  if (!tif) fail(path, "not a readable TIFF file (" + last_tiff_message + ")");
  return tif;
}

bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      const std::string na = a.substr(i, ie - i), nb = b.substr(j, je - j);
      const std::string ta = na.substr(std::min(na.find_first_not_of('0'), na.size()));
      const std::string tb = nb.substr(std::min(nb.find_first_not_of('0'), nb.size()));
      if (ta.size() != tb.size()) return ta.size() < tb.size();
      if (ta != tb) return ta < tb;
      i = ie;
      j = je;
      continue;
    }
    if (a[i] != b[j]) return a[i] < b[j];
    ++i;
    ++j;
  }
  return a.size() - i < b.size() - j;
}

}  // namespace

std::vector<std::string> natural_sorted_files(const std::string& folder) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(folder))
    if (entry.is_regular_file()) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".tif" || ext == ".tiff" || ext == ".TIF" || ext == ".TIFF") names.push_back(entry.path().filename());
    }
  std::sort(names.begin(), names.end(), natural_less);
  return names;
}

DenseVolume read_tiff(const std::string& path) {
  std::vector<std::string> files;
  if (std::filesystem::is_directory(path)) {
    for (const auto& name : natural_sorted_files(path)) files.push_back(path + "/" + name);
    if (files.empty()) fail(path, "the folder holds no .tif or .tiff files");
  } else {
    files.push_back(path);
  }
  // First pass: count the pages and check that they agree.
  PageFormat first;
  std::uint32_t pages = 0;
  for (const auto& file : files) {
    TiffHandle tif = open_tiff(file, "r");
    do {
      const std::string where = file + " page " + std::to_string(pages);
      const PageFormat f = page_format(tif.get(), where);
      if (pages == 0)
        first = f;
      else if (f.width != first.width || f.height != first.height || f.type != first.type)
        fail(where, std::to_string(f.width) + "x" + std::to_string(f.height) + " " + sample_type_name(f.type) +
                        " differs from the first page's " + std::to_string(first.width) + "x" +
                        std::to_string(first.height) + " " + sample_type_name(first.type));
      ++pages;
    } while (TIFFReadDirectory(tif.get()));
  }
  DenseVolume v = make_dense(Dims{first.width, first.height, pages}, first.type);
  const std::size_t page_bytes = std::size_t{first.width} * first.height * sample_size(first.type);
  std::uint32_t z = 0;
  for (const auto& file : files) {
    TiffHandle tif = open_tiff(file, "r");
    do {
      read_page(tif.get(), first, v.data.data() + z * page_bytes, file + " page " + std::to_string(z));
      ++z;
    } while (TIFFReadDirectory(tif.get()));
  }
  return v;
}

void write_tiff(const DenseVolume& volume, const std::string& path, const TiffWriteOptions& options) {
  install_handlers();
  const auto slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash);
  std::string temp = dir + "/.ivol-tmp-XXXXXX";
  const int fd = mkstemp(temp.data());
  if (fd < 0) fail(path, "cannot create a temporary file in " + dir);
  ::close(fd);
  // BigTIFF well before the 4 GiB limit of classic TIFF.
  const bool big = volume.data.size() > (3ull << 30);
  TIFF* raw = TIFFOpen(temp.c_str(), big ? "w8" : "w");
  if (!raw) {
    ::unlink(temp.c_str());
    fail(path, "cannot write: " + last_tiff_message);
  }
  TiffHandle tif(raw);
  const Dims& d = volume.dims;
  const std::size_t sample = sample_size(volume.type);
  const std::uint16_t bits = static_cast<std::uint16_t>(8 * sample);
  std::uint16_t format = SAMPLEFORMAT_UINT;
  if (volume.type == SampleType::Int16) format = SAMPLEFORMAT_INT;
  if (volume.type == SampleType::Float16 || volume.type == SampleType::Float32) format = SAMPLEFORMAT_IEEEFP;
  const std::uint32_t rows_per_strip =
      std::max<std::uint32_t>(1, static_cast<std::uint32_t>((64u << 10) / (d[0] * sample)));
  try {
    for (std::uint32_t z = 0; z < d[2]; ++z) {
      TIFFSetField(tif.get(), TIFFTAG_IMAGEWIDTH, d[0]);
      TIFFSetField(tif.get(), TIFFTAG_IMAGELENGTH, d[1]);
      TIFFSetField(tif.get(), TIFFTAG_BITSPERSAMPLE, bits);
      TIFFSetField(tif.get(), TIFFTAG_SAMPLESPERPIXEL, 1);
      TIFFSetField(tif.get(), TIFFTAG_SAMPLEFORMAT, format);
      TIFFSetField(tif.get(), TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
      TIFFSetField(tif.get(), TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
      TIFFSetField(tif.get(), TIFFTAG_ROWSPERSTRIP, rows_per_strip);
      TIFFSetField(tif.get(), TIFFTAG_SUBFILETYPE, FILETYPE_PAGE);
      TIFFSetField(tif.get(), TIFFTAG_PAGENUMBER, z, d[2]);
      if (options.compress) {
        TIFFSetField(tif.get(), TIFFTAG_COMPRESSION, COMPRESSION_ADOBE_DEFLATE);
        // Horizontal differencing helps integer slices; the floating-point
        // predictor would help floats but many readers lack it, so floats go
        // without one.
        if (format != SAMPLEFORMAT_IEEEFP) TIFFSetField(tif.get(), TIFFTAG_PREDICTOR, PREDICTOR_HORIZONTAL);
      } else {
        TIFFSetField(tif.get(), TIFFTAG_COMPRESSION, COMPRESSION_NONE);
      }
      const std::uint8_t* page = volume.data.data() + std::size_t{z} * d[0] * d[1] * sample;
      for (std::uint32_t y0 = 0, s = 0; y0 < d[1]; y0 += rows_per_strip, ++s) {
        const std::uint32_t rows = std::min(rows_per_strip, d[1] - y0);
        // libtiff's predictor works in place; give it a copy.
        std::vector<std::uint8_t> strip(page + std::size_t{y0} * d[0] * sample,
                                        page + (std::size_t{y0} + rows) * d[0] * sample);
        if (TIFFWriteEncodedStrip(tif.get(), s, strip.data(), static_cast<tmsize_t>(strip.size())) < 0)
          fail(path, "cannot write slice " + std::to_string(z) + ": " + last_tiff_message);
      }
      if (!TIFFWriteDirectory(tif.get()))
        fail(path, "cannot write slice " + std::to_string(z) + ": " + last_tiff_message);
    }
    tif.reset();
  } catch (...) {
    tif.reset();
    ::unlink(temp.c_str());
    throw;
  }
  if (::rename(temp.c_str(), path.c_str()) != 0) {
    ::unlink(temp.c_str());
    throw Error(ErrorClass::Io, path + ": cannot rename the finished file into place");
  }
}

}  // namespace ivol::convert
