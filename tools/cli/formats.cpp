#include "formats.hpp"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <optional>

#include "exactness.hpp"
#include "hdf5_io.hpp"
#include "itk_image_io.hpp"
#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "sizes.hpp"
#include "stdio_volume.hpp"
#include "tiff_io.hpp"
#include "vdb_io.hpp"

namespace ivol::cli {
namespace {

// OpenVDB writes a whole grid: gather the slabs as float32, write at the end;
// f16 samples make a half-float grid, integers a float32 one (which holds
// every u8, u16 and i16 value exactly).
class VdbSink final : public convert::SlabWriter {
 public:
  VdbSink(const std::string& path, const convert::DenseVolume& shape, float background, std::uint64_t memory_bytes,
          bool allow_lossy)
      : path_(path), volume_(shape), background_(background), allow_lossy_(allow_lossy) {
    half_ = shape.type == convert::SampleType::Float16;
    type_ = shape.type;
    volume_.type = convert::SampleType::Float32;
    // The whole volume is held as float32, and beside it the tree
    // write_vdb builds from it, and one slice as read (its stored bits and
    // samples; write() converts in place): weighed before anything is read,
    // so that a grid beyond --memory is a refusal naming its size, not an
    // allocation that fails (or a process killed) halfway. A source sizes
    // its slabs from what the volume and tree leave (held_bytes).
    const std::string what = path + ": an OpenVDB grid of " + convert::dims_text(shape.dims);
    const double slice =
        static_cast<double>(shape.dims[0]) * shape.dims[1] * (2.0 * convert::sample_size(shape.type) + sizeof(float));
    const double held = convert::vdb_output_bytes(shape.dims);
    convert::require_within_budget(held + slice, convert::memory_budget(memory_bytes),
                                   what + " (written whole: the volume as float32 and the grid's tree)");
    held_ = static_cast<std::uint64_t>(std::ceil(held));
    const std::uint64_t bytes = convert::slab_bytes(shape.dims, shape.dims[2], convert::SampleType::Float32, what);
    convert::checked_resize(volume_.data, bytes, what);
  }
  // Samples (native byte order) to float32 straight into the volume, with
  // no copy of the slab: exact for u8, u16, i16 and f32; binary16 by bit
  // operations, not through binary64 (which would quiet a signalling NaN),
  // so that the half-float grid stores the bits given.
  void write(const void* samples, std::uint32_t count) override {
    const std::size_t n = std::size_t{count} * volume_.dims[0] * volume_.dims[1];
    const auto* p = static_cast<const std::uint8_t*>(samples);
    std::uint8_t* floats = volume_.data.data() + at_;
    auto convert_as = [&](auto sample, auto to_float) {
      for (std::size_t i = 0; i < n; ++i) {
        decltype(sample) s;
        std::memcpy(&s, p + sizeof s * i, sizeof s);
        const float f = to_float(s);
        std::memcpy(floats + 4 * i, &f, 4);
      }
    };
    const auto widen = [](auto s) { return static_cast<float>(s); };
    switch (type_) {
      case convert::SampleType::UInt8:
        convert_as(std::uint8_t{}, widen);
        break;
      case convert::SampleType::UInt16:
        convert_as(std::uint16_t{}, widen);
        break;
      case convert::SampleType::Int16:
        convert_as(std::int16_t{}, widen);
        break;
      case convert::SampleType::Float16:
        convert_as(std::uint16_t{}, [](std::uint16_t h) { return binary16_to_float(h); });
        break;
      case convert::SampleType::Float32:
        std::memcpy(floats, p, n * 4);
        break;
    }
    at_ += n * 4;
  }
  std::uint64_t held_bytes() const override { return held_; }
  void finish() override {
    const std::string grid = half_ ? "a half-float grid" : "a float32 grid";
    const convert::LossTally loss =
        convert::write_vdb(volume_, path_, background_, "density", half_, [&](const convert::LossTally& l) {
          if (!allow_lossy_) convert::refuse_loss(l, volume_.voxel_count(), path_ + " as " + grid, grid);
        });
    if (!loss.exact())
      std::cerr << "ivol: lossy: " << path_ << " as " << grid << ": "
                << convert::describe_loss(loss, volume_.voxel_count(), grid) << "\n";
  }

 private:
  std::string path_;
  convert::DenseVolume volume_;
  convert::SampleType type_;
  float background_;
  bool allow_lossy_;
  bool half_ = false;
  std::size_t at_ = 0;
  std::uint64_t held_ = 0;  // the volume and the tree, as weighed
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
    case Format::MetaImage:
      return "mha";
    case Format::Nrrd:
      return "nrrd";
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
  if (key == "mha" || key == "mhd" || key == "metaimage" || key == ".mha" || key == ".mhd") return Format::MetaImage;
  if (key == "nrrd" || key == "nhdr" || key == ".nrrd" || key == ".nhdr") return Format::Nrrd;
  return std::nullopt;
}

const char* kKnown =
    "(extensions .ivol .raw .bin .vol .tif .tiff .h5 .hdf5 .vdb .mha .mhd .nrrd .nhdr, or a folder of TIFF files; or "
    "name it)";

}  // namespace

Format detect_format(const std::string& path, const std::string& name, const char* option) {
  if (!name.empty()) {
    if (const auto f = format_of(name)) return *f;
    throw UsageError(option, "'" + name + "' is not ivol, raw, tiff, hdf5, vdb, mha or nrrd");
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

std::unique_ptr<convert::SlabReader> open_source(const std::string& path, Format format, const ForeignOptions& options,
                                                 bool* rounded) {
  switch (format) {
    case Format::Raw:
      if (!options.raw_dims_given)
        throw UsageError("--dims", "a raw input needs its dimensions (--dims X,Y,Z --type T)");
      if (is_stdio(path)) return stdin_raw_slabs(options.raw);
      return convert::open_raw_slabs(path, options.raw);
    case Format::Tiff:
      return convert::open_tiff_slabs(path, convert::TiffFolderOptions{options.allow_gaps}, options.memory_bytes);
    case Format::Hdf5: {
      convert::Hdf5SourceInfo info;
      auto source = convert::open_hdf5_slabs(path, options.dataset, &info, options.memory_bytes);
      // ivol holds at most float32; HDF5 rounds float64 on the way, out of
      // sight, so the values cannot be checked: the rounding must be accepted.
      if (info.narrowed_to_f32 && !options.allow_lossy)
        throw Error(ErrorClass::InvalidArgument,
                    path + ": " + options.dataset +
                        " holds float64 samples, which ivol reads as float32, rounding every value float32 does not "
                        "hold (not counted); nothing written. --allow-lossy accepts the rounding");
      if (rounded) *rounded = info.narrowed_to_f32;
      if (info.narrowed_to_f32)
        std::cerr << "ivol: lossy: " << path << ": " << options.dataset
                  << ": float64 samples rounded to float32 (not counted)\n";
      return source;
    }
    case Format::Vdb:
      return convert::open_vdb_slabs(path, options.grid, nullptr, options.memory_bytes);
    case Format::MetaImage:
    case Format::Nrrd:
      return convert::open_itk_image_slabs(path);
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

bool writes_rows(Format format) { return format != Format::Vdb && format != Format::Ivol; }

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
      return convert::create_hdf5_slabs(path, shape, options.dataset, 4, options.band_rows);
    case Format::Vdb:
      return std::make_unique<VdbSink>(path, shape, options.background, options.memory_bytes, options.allow_lossy);
    case Format::MetaImage:
    case Format::Nrrd:
      return convert::create_itk_image_slabs(path, shape);
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

convert::SampleType natural_export_type(Format to, const Reader& reader) {
  if (to == Format::Vdb) return convert::natural_float_type(reader);
  const convert::SampleType natural = convert::natural_sample_type(reader);
  if ((to == Format::MetaImage || to == Format::Nrrd) && natural == convert::SampleType::Float16)
    return convert::SampleType::Float32;
  return natural;
}

void check_export_type(Format to, convert::SampleType type, const char* option) {
  if ((to == Format::MetaImage || to == Format::Nrrd) && type == convert::SampleType::Float16)
    throw UsageError(
        option, std::string("MetaImage and NRRD have no binary16 type; ") + option + " f32 holds every value exactly");
  if (to == Format::Vdb && type != convert::SampleType::Float32 && type != convert::SampleType::Float16)
    throw UsageError(option, std::string("OpenVDB grids hold float32 (") + option + " f32) or half-float (" + option +
                                 " f16) values, not " + convert::sample_type_name(type));
}

convert::LossCheck exactness_check(bool allow_lossy, const std::string& what, convert::SampleType type,
                                   convert::SampleType natural, const char* option) {
  if (allow_lossy) return {};
  const std::string hint =
      type == natural ? std::string() : std::string(option) + " " + convert::sample_type_name(natural);
  return [what, type, hint](const convert::LossTally& loss, std::uint64_t voxels) {
    convert::refuse_loss(loss, voxels, what, convert::sample_type_name(type), hint);
  };
}

void check_before_streaming(const std::string& output, Reader& reader, const Box& box, unsigned lod,
                            convert::SampleType type, const convert::LossCheck& check, bool salvage) {
  if (!is_stdio(output) || !check || convert::always_exact(reader.layout(), type)) return;
  class Discard final : public convert::SlabWriter {
   public:
    void write(const void*, std::uint32_t) override {}
    void finish() override {}
  } discard;
  std::vector<DamagedRegion> damaged;
  convert::export_from_ivol(reader, box, lod, type, discard, {}, salvage ? &damaged : nullptr, check);
}

}  // namespace ivol::cli
