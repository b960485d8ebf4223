#include "tiff_io.hpp"

#include <tiffio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <vector>

#include "ivol/error.hpp"
#include "sizes.hpp"
#include "slab_io.hpp"
#include "staged_file.hpp"
#include "tiff_folder.hpp"
#include "tiff_metadata.hpp"

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
  register_ivol_tiff_tag();
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
  // SGI's volumetric extension (tifffile's volumetric=True): a page that is
  // a whole 3-D block. Reading its first plane only would drop the rest.
  std::uint32_t depth = 1;
  TIFFGetFieldDefaulted(tif, TIFFTAG_IMAGEDEPTH, &depth);
  if (depth != 1)
    fail(where, "a volumetric page (ImageDepth " + std::to_string(depth) +
                    ") is not supported: write the volume as one page a slice, or a folder of slices");
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

// The buffer for one tile of a tiled page, weighed against `budget` before
// it is allocated (the tile's size comes from the file).
std::vector<std::uint8_t> tile_buffer(TIFF* tif, const PageFormat& f, std::uint64_t budget, const std::string& where,
                                      std::uint32_t& tw, std::uint32_t& th) {
  TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw);
  TIFFGetField(tif, TIFFTAG_TILELENGTH, &th);
  if (tw == 0 || th == 0) fail(where, "a tile of " + std::to_string(tw) + "x" + std::to_string(th) + " pixels");
  const std::string what = where + ": a tile of " + std::to_string(tw) + "x" + std::to_string(th) + " " +
                           sample_type_name(f.type) + " samples";
  const std::uint64_t tile_bytes = slab_bytes(Dims{tw, th, 1}, 1, f.type, what);
  require_within_budget(tile_bytes, budget, what);
  if (static_cast<std::uint64_t>(TIFFTileSize64(tif)) != tile_bytes)
    fail(where, "the tile size " + std::to_string(TIFFTileSize64(tif)) + " does not match " + std::to_string(tw) + "x" +
                    std::to_string(th) + " samples of " + sample_type_name(f.type));
  std::vector<std::uint8_t> tile;
  checked_resize(tile, tile_bytes, what);
  return tile;
}

// Reads rows y0 .. y0 + rows of the current page into `out`, one tile or
// one scanline at a time: what is held is one tile (within `budget`) or
// what libtiff keeps for a strip (its compressed bytes, bounded by the
// file), never the page.
// `next_row` is the row libtiff's scanline state is at for this page
// (kUnknownRow after anything else read it); it is updated.
constexpr std::uint32_t kUnknownRow = 0xFFFFFFFFu;
void read_page_rows(TIFF* tif, const PageFormat& f, std::uint32_t y0, std::uint32_t rows, std::uint8_t* out,
                    std::uint64_t budget, const std::string& where, std::uint32_t& next_row) {
  const std::size_t sample = sample_size(f.type);
  const std::size_t row_bytes = std::size_t{f.width} * sample;
  if (TIFFIsTiled(tif)) {
    std::uint32_t tw = 0, th = 0;
    std::vector<std::uint8_t> tile = tile_buffer(tif, f, budget, where, tw, th);
    // In 64 bits: a tile's side may be near 2^32 (weighed, but not small).
    const std::uint64_t end = std::uint64_t{y0} + rows;
    for (std::uint64_t ty = y0 / th * std::uint64_t{th}; ty < end; ty += th)
      for (std::uint64_t x0 = 0; x0 < f.width; x0 += tw) {
        if (TIFFReadTile(tif, tile.data(), static_cast<std::uint32_t>(x0), static_cast<std::uint32_t>(ty), 0, 0) < 0)
          fail(where, "cannot read a tile: " + last_tiff_message);
        const std::uint64_t w = std::min<std::uint64_t>(tw, f.width - x0);
        for (std::uint64_t y = std::max<std::uint64_t>(ty, y0); y < std::min<std::uint64_t>(ty + th, end); ++y)
          std::memcpy(out + (y - y0) * row_bytes + x0 * sample, tile.data() + (y - ty) * std::size_t{tw} * sample,
                      w * sample);
      }
    return;
  }
  // Scanlines: libtiff decodes a strip as far as the row asked for, so a
  // strip of 65535 rows is never held decoded. A compressed strip cannot be
  // entered in the middle: rows before y0 in its strip are decoded into a
  // scratch row, from the strip's start unless the state is already there.
  std::uint32_t rows_per_strip = f.height;
  TIFFGetFieldDefaulted(tif, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
  rows_per_strip = std::max<std::uint32_t>(1, std::min(rows_per_strip, f.height));
  const std::uint32_t strip_start = y0 / rows_per_strip * rows_per_strip;
  std::uint32_t y = next_row != kUnknownRow && next_row >= strip_start && next_row <= y0 ? next_row : strip_start;
  std::vector<std::uint8_t> scratch;
  if (y < y0) checked_resize(scratch, row_bytes, where + ": one row");
  next_row = kUnknownRow;  // until the rows below are read
  for (; y < y0 + rows; ++y) {
    std::uint8_t* row = y < y0 ? scratch.data() : out + (y - y0) * row_bytes;
    if (TIFFReadScanline(tif, row, y, 0) < 0)
      fail(where, "cannot read row " + std::to_string(y) + ": " + last_tiff_message);
  }
  next_row = y0 + rows;
}

// Reads one page into `out` (width * height samples, rows top to bottom).
void read_page(TIFF* tif, const PageFormat& f, std::uint8_t* out, std::uint64_t budget, const std::string& where) {
  const std::size_t sample = sample_size(f.type);
  const std::size_t row_bytes = std::size_t{f.width} * sample;
  if (TIFFIsTiled(tif)) {
    std::uint32_t unused = kUnknownRow;
    read_page_rows(tif, f, 0, f.height, out, budget, where, unused);
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

TiffHandle open_tiff(const std::string& path, const char* mode, std::uint64_t budget = kDefaultMemoryBytes) {
  install_handlers();
  // libtiff allocates what a file's tags ask for (strip and tag buffers);
  // no single allocation may exceed what the conversion may hold.
  std::unique_ptr<TIFFOpenOptions, void (*)(TIFFOpenOptions*)> options(TIFFOpenOptionsAlloc(), TIFFOpenOptionsFree);
  if (options) TIFFOpenOptionsSetMaxSingleMemAlloc(options.get(), static_cast<tmsize_t>(budget));
  TiffHandle tif(TIFFOpenExt(path.c_str(), mode, options.get()));
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

namespace {

// Pages of one multi-page file or of a folder of files, read in order; going
// back (for the halo of a slab) reopens.
class TiffSlabReader final : public SlabReader {
 public:
  TiffSlabReader(const std::string& path, const TiffFolderOptions& options, std::uint64_t budget) : budget_(budget) {
    if (std::filesystem::is_directory(path)) {
      TiffFolder folder = scan_tiff_folder(path, options);
      files_ = std::move(folder.files);
      shape_.notes = std::move(folder.notes);
    } else {
      files_.push_back(path);
    }
    // Count the pages and check that they agree; a page is named by its own
    // file (and its page within that file when the file has several).
    std::string first_where;
    for (std::size_t f = 0; f < files_.size(); ++f) {
      TiffHandle tif = open_tiff(files_[f], "r", budget_);
      if (f == 0) read_tiff_metadata(tif.get(), files_[0], shape_);
      tdir_t page_in_file = 0;
      do {
        if (page_in_file == 1 && files_.size() > 1) throw several_pages_among_files(files_[f], "slice");
        const bool several = page_in_file > 0 || !TIFFLastDirectory(tif.get());
        const std::string where = files_[f] + (several ? " page " + std::to_string(page_in_file) : std::string());
        const PageFormat page = page_format(tif.get(), where);
        if (pages_.empty()) {
          format_ = page;
          first_where = where;
        } else if (page.width != format_.width || page.height != format_.height || page.type != format_.type) {
          throw Error(ErrorClass::Malformed, where + ": " + std::to_string(page.width) + "x" +
                                                 std::to_string(page.height) + " " + sample_type_name(page.type) +
                                                 " differs from " + first_where + ": " + std::to_string(format_.width) +
                                                 "x" + std::to_string(format_.height) + " " +
                                                 sample_type_name(format_.type));
        }
        pages_.push_back({f, TIFFCurrentDirectory(tif.get())});
        ++page_in_file;
      } while (TIFFReadDirectory(tif.get()));
    }
    shape_.dims = Dims{format_.width, format_.height, static_cast<std::uint32_t>(pages_.size())};
    shape_.type = format_.type;
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const std::uint64_t page_bytes =
        slab_bytes(Dims{format_.width, format_.height, 1}, 1, format_.type, files_.front() + ": a page");
    scan_row_ = kUnknownRow;  // strips read whole leave no scanline state
    for (std::uint32_t z = z0; z < z0 + count; ++z)
      read_page(go_to_page(z), format_, static_cast<std::uint8_t*>(out) + (z - z0) * page_bytes, budget_,
                files_[pages_.at(z).file] + " page " + std::to_string(z));
  }

  bool reads_rows() const override { return true; }
  bool thick_reads_pay() const override { return false; }  // pages are read one by one
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override {
    if (y0 > format_.height || rows > format_.height - y0)
      fail(files_.front(), "rows " + std::to_string(y0) + " .. " + std::to_string(std::uint64_t{y0} + rows) +
                               " are outside a page of " + std::to_string(format_.height));
    TIFF* tif = go_to_page(z);
    if (z != scan_page_) scan_row_ = kUnknownRow;
    scan_page_ = z;
    read_page_rows(tif, format_, y0, rows, static_cast<std::uint8_t*>(out), budget_,
                   files_[pages_.at(z).file] + " page " + std::to_string(z), scan_row_);
  }

 private:
  struct Page {
    std::size_t file;
    tdir_t directory;
  };

  // The open file, at page z's directory.
  TIFF* go_to_page(std::uint32_t z) {
    const Page& page = pages_.at(z);
    if (!open_ || open_file_ != page.file) {
      open_ = open_tiff(files_[page.file], "r", budget_);
      open_file_ = page.file;
      scan_row_ = kUnknownRow;
    }
    // Pages are read in order: the next one is the next directory in the
    // chain. TIFFSetDirectory walks the chain from the first page, so it
    // is kept for going back (a slab's halo); with it for every page, a
    // file of 100 000 pages took minutes.
    const tdir_t current = TIFFCurrentDirectory(open_.get());
    if (current != page.directory) {
      const bool next = page.directory == current + 1 && TIFFReadDirectory(open_.get()) &&
                        TIFFCurrentDirectory(open_.get()) == page.directory;
      if (!next && !TIFFSetDirectory(open_.get(), page.directory))
        fail(files_[page.file], "cannot find page " + std::to_string(page.directory));
      scan_row_ = kUnknownRow;
    }
    return open_.get();
  }

  std::uint64_t budget_;
  // Where libtiff's scanline reading stands: page and next row.
  std::uint32_t scan_page_ = kUnknownRow;
  std::uint32_t scan_row_ = kUnknownRow;
  std::vector<std::string> files_;
  std::vector<Page> pages_;
  PageFormat format_;
  TiffHandle open_;
  std::size_t open_file_ = 0;
};

class TiffSlabWriter final : public SlabWriter {
 public:
  TiffSlabWriter(const std::string& path, const DenseVolume& shape, bool compress)
      : path_(path), shape_(shape_of(shape)), dims_(shape.dims), type_(shape.type), compress_(compress), staged_(path) {
    install_handlers();
    // BigTIFF well before the 4 GiB limit of classic TIFF.
    const bool big = slab_bytes(dims_, dims_[2], type_, path) > (3ull << 30);
    tif_.reset(TIFFOpen(staged_.temp_path().c_str(), big ? "w8" : "w"));
    if (!tif_) fail(path, "cannot write: " + last_tiff_message);
    // Strips of about 64 KiB (one row where a row is longer).
    rows_per_strip_ = static_cast<std::uint32_t>(
        std::clamp<std::uint64_t>((64u << 10) / (std::uint64_t{dims_[0]} * sample_size(type_)), 1, UINT32_MAX));
  }

  void write(const void* samples, std::uint32_t count) override {
    const auto* page = static_cast<const std::uint8_t*>(samples);
    const std::size_t page_bytes = std::size_t{dims_[0]} * dims_[1] * sample_size(type_);
    for (std::uint32_t n = 0; n < count; ++n) write_rows(page + n * page_bytes, dims_[1]);
  }

  // Rows gather into a strip (about 64 KiB), which is encoded when full or
  // when its page ends; a page ends with its directory.
  bool writes_rows() const override { return true; }
  void write_rows(const void* samples, std::uint32_t rows) override {
    const std::size_t row_bytes = std::size_t{dims_[0]} * sample_size(type_);
    const auto* p = static_cast<const std::uint8_t*>(samples);
    while (rows > 0) {
      if (z_ >= dims_[2]) fail(path_, "more rows than " + std::to_string(dims_[2]) + " pages hold");
      if (row_ == 0 && strip_.empty()) begin_page();
      const std::uint32_t strip_rows = std::min(rows_per_strip_, dims_[1] - strip_first_row());
      const std::uint32_t take =
          std::min<std::uint32_t>(rows, strip_rows - static_cast<std::uint32_t>(strip_.size() / row_bytes));
      strip_.insert(strip_.end(), p, p + std::size_t{take} * row_bytes);
      p += std::size_t{take} * row_bytes;
      rows -= take;
      row_ += take;
      if (strip_.size() == std::size_t{strip_rows} * row_bytes) {
        // libtiff's predictor works in place: the strip is our copy.
        errno = 0;
        if (TIFFWriteEncodedStrip(tif_.get(), strip_first_row() / rows_per_strip_, strip_.data(),
                                  static_cast<tmsize_t>(strip_.size())) < 0)
          write_failed("cannot write slice " + std::to_string(z_));
        strip_.clear();
      }
      if (row_ == dims_[1]) {
        errno = 0;
        if (!TIFFWriteDirectory(tif_.get())) write_failed("cannot write slice " + std::to_string(z_));
        row_ = 0;
        ++z_;
      }
    }
  }

  void finish() override {
    if (z_ != dims_[2] || row_ != 0)
      fail(path_, std::to_string(z_) + " of " + std::to_string(dims_[2]) + " slices written");
    // TIFFClose reports nothing; whatever is still buffered is written here,
    // where a failure can still be seen.
    errno = 0;
    if (!TIFFFlush(tif_.get())) write_failed("cannot finish the file");
    tif_.reset();
    staged_.commit();
  }

 private:
  // A failed write is an I/O error (a full disk, a quota), with the system's
  // reason when libtiff's write(2) left one.
  // The first row of the strip being gathered.
  std::uint32_t strip_first_row() const {
    const std::size_t row_bytes = std::size_t{dims_[0]} * sample_size(type_);
    return row_ - static_cast<std::uint32_t>(strip_.size() / row_bytes);
  }

  void begin_page() {
    const std::uint16_t bits = static_cast<std::uint16_t>(8 * sample_size(type_));
    std::uint16_t format = SAMPLEFORMAT_UINT;
    if (type_ == SampleType::Int16) format = SAMPLEFORMAT_INT;
    if (type_ == SampleType::Float16 || type_ == SampleType::Float32) format = SAMPLEFORMAT_IEEEFP;
    TIFF* tif = tif_.get();
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, dims_[0]);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, dims_[1]);
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, bits);
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, format);
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, rows_per_strip_);
    TIFFSetField(tif, TIFFTAG_SUBFILETYPE, FILETYPE_PAGE);
    TIFFSetField(tif, TIFFTAG_PAGENUMBER, z_, dims_[2]);
    write_tiff_metadata(tif, shape_, z_, dims_[2]);
    if (compress_) {
      TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_ADOBE_DEFLATE);
      // Horizontal differencing helps integer slices; the floating-point
      // predictor would help floats but many readers lack it, so floats go
      // without one.
      if (format != SAMPLEFORMAT_IEEEFP) TIFFSetField(tif, TIFFTAG_PREDICTOR, PREDICTOR_HORIZONTAL);
    } else {
      TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_NONE);
    }
  }

  [[noreturn]] void write_failed(const std::string& what) const {
    const int e = errno;
    throw Error(ErrorClass::Io, path_ + ": " + what + ": " + last_tiff_message +
                                    (e != 0 ? std::string(" (") + std::strerror(e) + ")" : std::string()));
  }

  std::string path_;
  DenseVolume shape_;
  Dims dims_;
  SampleType type_;
  bool compress_;
  StagedFile staged_;  // declared before tif_: the file closes before it is removed
  TiffHandle tif_;
  std::uint32_t rows_per_strip_ = 1;
  std::uint32_t z_ = 0;              // the page being written
  std::uint32_t row_ = 0;            // rows of it given so far
  std::vector<std::uint8_t> strip_;  // rows of the strip not yet encoded
};

}  // namespace

std::unique_ptr<SlabReader> open_tiff_slabs(const std::string& path, const TiffFolderOptions& options,
                                            std::uint64_t memory_bytes) {
  return std::make_unique<TiffSlabReader>(path, options, memory_budget(memory_bytes));
}

std::unique_ptr<SlabWriter> create_tiff_slabs(const std::string& path, const DenseVolume& shape, bool compress) {
  return std::make_unique<TiffSlabWriter>(path, shape, compress);
}

DenseVolume read_tiff(const std::string& path, const TiffFolderOptions& options) {
  auto reader = open_tiff_slabs(path, options);
  DenseVolume v = shape_of(reader->shape());
  v.data.resize(v.voxel_count() * sample_size(v.type));
  reader->read(0, v.dims[2], v.data.data());
  return v;
}

void write_tiff(const DenseVolume& volume, const std::string& path, const TiffWriteOptions& options) {
  auto writer = create_tiff_slabs(path, volume, options.compress);
  writer->write(volume.data.data(), volume.dims[2]);
  writer->finish();
}

}  // namespace ivol::convert
