#include "formats.hpp"

#include <cstring>
#include <filesystem>
#include <optional>

#include "hdf5_io.hpp"
#include "ivol/error.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "sizes.hpp"
#include "stdio_volume.hpp"
#include "tiff_io.hpp"
#include "vdb_io.hpp"

namespace ivol::cli {
namespace {

// OpenVDB writes a whole grid: gather the slabs, write at the end.
class VdbSink final : public convert::SlabWriter {
 public:
  VdbSink(const std::string& path, const convert::DenseVolume& shape, float background, std::uint64_t memory_bytes)
      : path_(path), volume_(shape), background_(background) {
    if (volume_.type != convert::SampleType::Float32)
      throw Error(ErrorClass::InvalidArgument, path + ": OpenVDB grids hold float32 values (--type f32)");
    // The whole volume is held, and once more as the floats write_vdb builds
    // the grid from.
    const std::string what = path + ": an OpenVDB grid of " + convert::dims_text(shape.dims);
    const std::uint64_t bytes = convert::slab_bytes(shape.dims, shape.dims[2], shape.type, what);
    convert::require_within_budget(convert::checked_mul(bytes, 2, what), convert::memory_budget(memory_bytes),
                                   what + " (OpenVDB grids are written whole)");
    convert::checked_resize(volume_.data, bytes, what);
  }
  void write(const void* samples, std::uint32_t count) override {
    const std::uint64_t bytes = convert::slab_bytes(volume_.dims, count, volume_.type, path_);
    std::memcpy(volume_.data.data() + at_, samples, bytes);
    at_ += bytes;
  }
  void finish() override { convert::write_vdb(volume_, path_, background_); }

 private:
  std::string path_;
  convert::DenseVolume volume_;
  float background_;
  std::size_t at_ = 0;
};

}  // namespace

const char* format_name(Format format) {
  switch (format) {
    case Format::Ivol:
      return "ivol";
    case Format::Raw:
      return "raw";
    case Format::Tiff:
      return "tiff";
    case Format::Hdf5:
      return "hdf5";
    case Format::Vdb:
      return "vdb";
  }
  return "?";
}

namespace {

std::optional<Format> format_of(const std::string& key) {
  if (key == "ivol" || key == ".ivol") return Format::Ivol;
  if (key == "raw" || key == ".raw" || key == ".bin" || key == ".vol") return Format::Raw;
  if (key == "tiff" || key == "tif" || key == ".tif" || key == ".tiff") return Format::Tiff;
  if (key == "hdf5" || key == ".h5" || key == ".hdf5" || key == ".hdf") return Format::Hdf5;
  if (key == "vdb" || key == ".vdb") return Format::Vdb;
  return std::nullopt;
}

const char* kKnown =
    "(extensions .ivol .raw .bin .vol .tif .tiff .h5 .hdf5 .vdb, or a folder of TIFF files; or name it)";

}  // namespace

Format detect_format(const std::string& path, const std::string& name, const char* option) {
  if (!name.empty()) {
    if (const auto f = format_of(name)) return *f;
    throw UsageError(option, "'" + name + "' is not ivol, raw, tiff, hdf5 or vdb");
  }
  if (is_stdio(path)) return Format::Raw;
  if (const auto f = format_of(lower_extension(path))) return *f;
  if (std::filesystem::is_directory(path)) return Format::Tiff;
  throw UsageError(option, "cannot tell the format of '" + path + "' " + kKnown);
}

Format output_format(const std::string& path, const std::string& name, const char* option) {
  // A plain Format and a flag, not an optional: GCC 12 warns (wrongly) that
  // an optional enum may be read uninitialised.
  const bool has_name = !name.empty();
  const Format named = has_name ? detect_format(path, name, "--to") : Format::Raw;
  if (is_stdio(path)) {
    if (has_name && named != Format::Raw)
      throw UsageError(option, std::string("'-' (standard output) takes raw output only, not ") + format_name(named));
    return Format::Raw;
  }
  const std::optional<Format> by_extension = format_of(lower_extension(path));
  if (!has_name) {
    if (by_extension) return *by_extension;
    throw UsageError(option, "cannot tell the format of '" + path + "' " + kKnown);
  }
  if (by_extension && *by_extension != named)
    throw UsageError(option, "'" + path + "' is named as " + format_name(*by_extension) + " but " + format_name(named) +
                                 " would be written; give it a ." +
                                 (named == Format::Tiff ? "tif" : format_name(named)) + " name");
  return named;
}

std::unique_ptr<convert::SlabReader> open_source(const std::string& path, Format format,
                                                 const ForeignOptions& options) {
  switch (format) {
    case Format::Raw:
      if (!options.raw_dims_given)
        throw UsageError("--dims", "a raw input needs its dimensions (--dims X,Y,Z --type T)");
      if (is_stdio(path)) return stdin_raw_slabs(options.raw);
      return convert::open_raw_slabs(path, options.raw);
    case Format::Tiff:
      return convert::open_tiff_slabs(path, convert::TiffFolderOptions{options.allow_gaps});
    case Format::Hdf5:
      return convert::open_hdf5_slabs(path, options.dataset, nullptr, options.memory_bytes);
    case Format::Vdb:
      return convert::memory_slabs(convert::read_vdb(path, options.grid, options.memory_bytes).volume);
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

std::unique_ptr<convert::SlabWriter> create_sink(const std::string& path, Format format,
                                                 const convert::DenseVolume& shape, const ForeignOptions& options) {
  if (is_stdio(path)) {
    if (format != Format::Raw) throw UsageError("-o", "'-' (standard output) takes raw output only");
    return stdout_raw_slabs(shape, options.big_endian);
  }
  switch (format) {
    case Format::Raw:
      return convert::create_raw_slabs(path, shape, options.big_endian);
    case Format::Tiff:
      return convert::create_tiff_slabs(path, shape);
    case Format::Hdf5:
      return convert::create_hdf5_slabs(path, shape, options.dataset);
    case Format::Vdb:
      return std::make_unique<VdbSink>(path, shape, options.background, options.memory_bytes);
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

}  // namespace ivol::cli
