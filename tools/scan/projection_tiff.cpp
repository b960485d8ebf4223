// TIFF projections: one page per view, read strip by strip or tile by tile so
// that a band of rows decodes only the strips or tiles that hold it.
#include <glob.h>
#include <tiffio.h>

#include <algorithm>
#include <cctype>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include "ivol/error.hpp"
#include "projection_io.hpp"
#include "tiff_io.hpp"

namespace ivol::convert {
namespace {

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw Error(ErrorClass::InvalidArgument, where + ": " + what);
}

// Digit runs compared as numbers, as natural_sorted_files orders a folder.
bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  auto digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
  while (i < a.size() && j < b.size()) {
    if (digit(a[i]) && digit(b[j])) {
      while (i < a.size() && a[i] == '0' && i + 1 < a.size() && digit(a[i + 1])) ++i;  // leading zeros
      while (j < b.size() && b[j] == '0' && j + 1 < b.size() && digit(b[j + 1])) ++j;
      std::size_t ie = i, je = j;
      while (ie < a.size() && digit(a[ie])) ++ie;
      while (je < b.size() && digit(b[je])) ++je;
      if (ie - i != je - j) return ie - i < je - j;
      const int order = a.compare(i, ie - i, b, j, je - j);
      if (order != 0) return order < 0;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

// A TIFF opened with its own error handler (libtiff's global handlers belong
// to tiff_io.cpp), so that each failure carries libtiff's reason.
class TiffFile {
 public:
  explicit TiffFile(const std::string& path) : path_(path), message_(std::make_unique<std::string>()) {
    TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetErrorHandlerExtR(options, remember, message_.get());
    TIFFOpenOptionsSetWarningHandlerExtR(options, ignore, nullptr);
    tif_ = TIFFOpenExt(path.c_str(), "r", options);
    TIFFOpenOptionsFree(options);
    if (!tif_) fail(path, "not a readable TIFF file (" + reason() + ")");
  }
  ~TiffFile() {
    if (tif_) TIFFClose(tif_);
  }
  TiffFile(const TiffFile&) = delete;
  TiffFile& operator=(const TiffFile&) = delete;

  TIFF* get() const { return tif_; }
  const std::string& path() const { return path_; }
  std::string reason() const { return message_->empty() ? "no reason given" : *message_; }

 private:
  static int remember(TIFF*, void* user_data, const char* module, const char* format, va_list args) {
    char text[512];
    std::vsnprintf(text, sizeof text, format, args);
    *static_cast<std::string*>(user_data) = std::string(module ? module : "libtiff") + ": " + text;
    return 1;  // handled: libtiff's global handler stays silent
  }
  static int ignore(TIFF*, void*, const char*, const char*, va_list) { return 1; }

  std::string path_;
  std::unique_ptr<std::string> message_;  // stable address for the handler
  TIFF* tif_ = nullptr;
};

struct PageFormat {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  bool is_float = false;  // float32, else uint16
};

PageFormat page_format(TIFF* tif, const std::string& where) {
  PageFormat f;
  std::uint16_t bits = 0, samples = 1, format = SAMPLEFORMAT_UINT;
  TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &f.width);
  TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &f.height);
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &samples);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &format);
  if (samples != 1) fail(where, std::to_string(samples) + " samples per pixel; a projection has one");
  std::uint32_t depth = 1;  // SGI's volumetric extension: a page that is a 3-D block
  TIFFGetFieldDefaulted(tif, TIFFTAG_IMAGEDEPTH, &depth);
  if (depth != 1)
    fail(where, "a volumetric page (ImageDepth " + std::to_string(depth) + ") is not supported: one page a projection");
  if (bits == 16 && format == SAMPLEFORMAT_UINT)
    f.is_float = false;
  else if (bits == 32 && format == SAMPLEFORMAT_IEEEFP)
    f.is_float = true;
  else
    fail(where, std::to_string(bits) + "-bit samples of sample format " + std::to_string(format) +
                    " are not supported (16-bit unsigned or 32-bit float)");
  if (f.width == 0 || f.height == 0) fail(where, "an empty page");
  if (f.width > 1u << 30 || f.height > 1u << 30) fail(where, "the page is too large");
  return f;
}

void convert_row(const std::uint8_t* in, std::size_t count, bool is_float, double* out) {
  for (std::size_t i = 0; i < count; ++i) {
    if (is_float) {
      float v;
      std::memcpy(&v, in + 4 * i, 4);
      out[i] = v;
    } else {
      std::uint16_t v;
      std::memcpy(&v, in + 2 * i, 2);
      out[i] = v;
    }
  }
}

// Rows [r0, r1) of the current page, decoding only the strips or tiles that
// hold them (libtiff decodes native byte order).
void read_band(const TiffFile& file, const PageFormat& f, std::uint32_t r0, std::uint32_t r1, double* out,
               const std::string& where) {
  TIFF* tif = file.get();
  const std::size_t sample = f.is_float ? 4 : 2;
  if (TIFFIsTiled(tif)) {
    std::uint32_t tw = 0, th = 0;
    TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw);
    TIFFGetField(tif, TIFFTAG_TILELENGTH, &th);
    if (tw == 0 || th == 0) fail(where, "tiles of size 0");
    std::vector<std::uint8_t> tile(static_cast<std::size_t>(TIFFTileSize(tif)));
    if (tile.size() < std::size_t{tw} * th * sample) fail(where, "tiles smaller than their stated size");
    for (std::uint32_t y0 = r0 / th * th; y0 < r1; y0 += th)
      for (std::uint32_t x0 = 0; x0 < f.width; x0 += tw) {
        if (TIFFReadTile(tif, tile.data(), x0, y0, 0, 0) < 0)
          fail(where, "cannot read the tile at row " + std::to_string(y0) + ", column " + std::to_string(x0) + ": " +
                          file.reason());
        const std::uint32_t w = std::min(tw, f.width - x0);
        for (std::uint32_t y = std::max(y0, r0); y < std::min(y0 + th, r1); ++y)
          convert_row(tile.data() + std::size_t{y - y0} * tw * sample, w, f.is_float,
                      out + std::size_t{y - r0} * f.width + x0);
      }
    return;
  }
  std::uint32_t rows_per_strip = f.height;
  TIFFGetFieldDefaulted(tif, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
  rows_per_strip = std::clamp<std::uint32_t>(rows_per_strip, 1, f.height);
  const std::size_t row_bytes = std::size_t{f.width} * sample;
  std::vector<std::uint8_t> strip(std::size_t{rows_per_strip} * row_bytes);
  for (std::uint32_t s = r0 / rows_per_strip; s * rows_per_strip < r1; ++s) {
    const std::uint32_t y0 = s * rows_per_strip;
    const std::uint32_t rows = std::min(rows_per_strip, f.height - y0);
    const tmsize_t got = TIFFReadEncodedStrip(tif, s, strip.data(), static_cast<tmsize_t>(rows * row_bytes));
    if (got < 0) fail(where, "cannot read strip " + std::to_string(s) + ": " + file.reason());
    if (static_cast<std::size_t>(got) < rows * row_bytes) fail(where, "strip " + std::to_string(s) + " is short");
    for (std::uint32_t y = std::max(y0, r0); y < std::min(y0 + rows, r1); ++y)
      convert_row(strip.data() + std::size_t{y - y0} * row_bytes, f.width, f.is_float,
                  out + std::size_t{y - r0} * f.width);
  }
}

struct Page {
  std::size_t file;
  tdir_t directory;
};

// Every page of every file, checked to share one size (and, for the
// projections, one sample type, and one page a file when there are several
// files: a view each).
std::vector<Page> list_pages(const std::vector<std::string>& files, PageFormat& format, bool projections) {
  std::vector<Page> pages;
  for (std::size_t i = 0; i < files.size(); ++i) {
    TiffFile file(files[i]);
    do {
      const tdir_t directory = TIFFCurrentDirectory(file.get());
      if (projections && files.size() > 1 && directory > 0) throw several_pages_among_files(files[i], "projection");
      const std::string where = files[i] + " page " + std::to_string(directory);
      const PageFormat page = page_format(file.get(), where);
      if (pages.empty() && format.width == 0) format = page;
      if (page.width != format.width || page.height != format.height || (projections && page.is_float != format.is_float))
        fail(where, std::to_string(page.width) + "x" + std::to_string(page.height) +
                        (page.is_float ? " float32" : " uint16") + " differs from the projections' " +
                        std::to_string(format.width) + "x" + std::to_string(format.height) +
                        (format.is_float ? " float32" : " uint16"));
      pages.push_back({i, directory});
    } while (TIFFReadDirectory(file.get()));
  }
  return pages;
}

std::vector<double> tiff_field(const std::vector<std::string>& sources, PageFormat format, const char* kind) {
  if (sources.empty()) return {};  // no field of this kind
  const std::size_t pixels = std::size_t{format.width} * format.height;
  FieldAverage average(pixels);
  std::vector<double> image(pixels);
  for (const std::string& source : sources) {
    const std::vector<std::string> files = resolve_tiff_files(source);
    PageFormat field = format;
    for (const Page& page : list_pages(files, field, false)) {
      TiffFile file(files[page.file]);
      const std::string where = files[page.file] + " page " + std::to_string(page.directory) + " (" + kind + " field)";
      if (!TIFFSetDirectory(file.get(), page.directory)) fail(where, "cannot find the page: " + file.reason());
      read_band(file, page_format(file.get(), where), 0, format.height, image.data(), where);
      average.add(image.data());
    }
  }
  return average.mean();
}

class TiffProjections final : public ProjectionReader {
 public:
  TiffProjections(std::vector<std::string> files, std::vector<Page> pages, PageFormat format)
      : ProjectionReader(files.size() == 1 ? files[0] : files[0] + " and " + std::to_string(files.size() - 1) + " more",
                         static_cast<int>(format.width), static_cast<int>(format.height), pages.size()),
        files_(std::move(files)),
        pages_(std::move(pages)),
        format_(format) {}

  void enable_intensities(const IntensityOptions& intensity) {
    set_fields(tiff_field(intensity.flat_paths, format_, "flat"), tiff_field(intensity.dark_paths, format_, "dark"),
               intensity);
  }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    const Page& page = pages_[view];
    const std::string where = files_[page.file] + " page " + std::to_string(page.directory) + " (view " +
                              std::to_string(view) + ", rows " + std::to_string(row_begin) + ".." +
                              std::to_string(row_end) + ")";
    if (!open_ || open_file_ != page.file) {
      open_.reset();
      open_ = std::make_unique<TiffFile>(files_[page.file]);
      open_file_ = page.file;
    }
    if (TIFFCurrentDirectory(open_->get()) != page.directory && !TIFFSetDirectory(open_->get(), page.directory))
      fail(where, "cannot find the page: " + open_->reason());
    read_band(*open_, format_, static_cast<std::uint32_t>(row_begin), static_cast<std::uint32_t>(row_end), out, where);
  }

 private:
  std::vector<std::string> files_;
  std::vector<Page> pages_;
  PageFormat format_;
  std::unique_ptr<TiffFile> open_;
  std::size_t open_file_ = 0;
};

}  // namespace

std::vector<std::string> resolve_tiff_files(const std::string& source) {
  std::error_code ec;
  std::vector<std::string> files;
  if (std::filesystem::is_directory(source, ec)) {
    // One file per view, checked as a volume's slices are: a missing view
    // would shift every later angle. A glob names the files to use instead.
    TiffFolderOptions options;
    options.gap_hint = "every view needs its projection; name the files to use with a pattern (\"folder/p*.tif\")";
    return scan_tiff_folder(source, options).files;
  }
  if (source.find_first_of("*?[") == std::string::npos) return {source};
  glob_t matches{};
  const int status = ::glob(source.c_str(), 0, nullptr, &matches);
  for (std::size_t i = 0; status == 0 && i < matches.gl_pathc; ++i) files.emplace_back(matches.gl_pathv[i]);
  ::globfree(&matches);
  if (status == GLOB_NOMATCH || files.empty()) fail(source, "no file matches the pattern");
  if (status != 0) fail(source, "cannot list the files that match the pattern");
  std::sort(files.begin(), files.end(), natural_less);
  return files;
}

std::unique_ptr<ProjectionReader> open_tiff_projections(const std::string& source, StoredQuantity quantity,
                                                        const IntensityOptions& intensity) {
  return open_tiff_projections(resolve_tiff_files(source), quantity, intensity);
}

std::unique_ptr<ProjectionReader> open_tiff_projections(const std::vector<std::string>& files, StoredQuantity quantity,
                                                        const IntensityOptions& intensity) {
  if (files.empty()) throw Error(ErrorClass::InvalidArgument, "no TIFF projection files given");
  PageFormat format;
  std::vector<Page> pages = list_pages(files, format, true);
  auto reader = std::make_unique<TiffProjections>(files, std::move(pages), format);
  const bool intensities = !format.is_float || quantity == StoredQuantity::Intensities;
  if (!intensities && (!intensity.flat_paths.empty() || !intensity.dark_paths.empty()))
    fail(files[0], "flat or dark fields given for line integrals");
  if (intensities) reader->enable_intensities(intensity);
  return reader;
}

}  // namespace ivol::convert
