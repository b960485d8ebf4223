#include "ivol_io.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/writer.hpp"

namespace ivol::convert {

KeepRule parse_keep_rule(const std::string& text) {
  KeepRule rule;
  bool have_threshold = false;
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t comma = std::min(text.find(',', at), text.size());
    const std::string item = text.substr(at, comma - at);
    const std::size_t eq = item.find('=');
    const std::string key = item.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : item.substr(eq + 1);
    try {
      if (key == "threshold" && value == "otsu")
        rule.otsu = have_threshold = true;
      else if (key == "threshold")
        rule.threshold = std::stof(value), have_threshold = true;
      else if (key == "margin")
        rule.margin = static_cast<unsigned>(std::stoul(value));
      else
        throw std::invalid_argument(key);
    } catch (const std::exception&) {
      throw Error(ErrorClass::InvalidArgument, "--keep: '" + item + "' is not threshold=VALUE|otsu or margin=VOXELS");
    }
    at = comma + 1;
  }
  if (!have_threshold) throw Error(ErrorClass::InvalidArgument, "--keep: threshold=VALUE|otsu is required");
  return rule;
}

ValueEncoding lossless_encoding(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
    case SampleType::UInt16:
    case SampleType::Int16:
      return ValueEncoding::UInt16;
    case SampleType::Float16:
      return ValueEncoding::Binary16;
    case SampleType::Float32:
      return ValueEncoding::Float32;
  }
  return ValueEncoding::Float32;
}

ImportReport import_to_ivol(const DenseVolume& volume, const std::string& path, const ImportOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ImportReport report;
  report.encoding = options.encoding.value_or(lossless_encoding(volume.type));
  BuildOptions build;
  build.encoding = report.encoding;
  const bool integer_source =
      volume.type == SampleType::UInt8 || volume.type == SampleType::UInt16 || volume.type == SampleType::Int16;
  if (build.encoding == ValueEncoding::UInt16 && volume.type == SampleType::Int16) build.value_offset = -32768.0;
  if (build.encoding == ValueEncoding::UInt16 && !integer_source)
    throw Error(ErrorClass::InvalidArgument,
                std::string("--encoding uint16 needs integer samples; this volume holds ") +
                    sample_type_name(volume.type) + " (use binary16 or float32)");
  report.value_scale = build.value_scale;
  report.value_offset = build.value_offset;

  std::vector<float> as_float;
  std::vector<std::uint16_t> as_codes;
  const bool codes = build.encoding == ValueEncoding::UInt16;
  if (codes) {
    as_codes.resize(volume.voxel_count());
    for (std::uint64_t i = 0; i < as_codes.size(); ++i)
      as_codes[i] = static_cast<std::uint16_t>(volume.value(i) - build.value_offset);
  }
  if (!codes || options.keep) as_float = volume.to_float();

  std::vector<std::uint8_t> keep;
  if (options.keep) {
    report.threshold = options.keep->otsu ? otsu_threshold(as_float.data(), as_float.size()) : options.keep->threshold;
    keep = threshold_keep_mask(as_float.data(), volume.dims, report.threshold, options.keep->margin);
    build.keep_mask = keep.data();
  }
  const BuildResult built =
      codes ? build_octree(as_codes.data(), volume.dims, build) : build_octree(as_float.data(), volume.dims, build);
  report.lossless = built.lossless;
  report.max_abs_error = built.max_abs_error;
  report.kept_voxels = built.kept_voxels;

  Metadata metadata = options.metadata;
  if (volume.has_geometry) {
    metadata.voxel_size = volume.voxel_size;
    metadata.origin = volume.origin;
    metadata.unit = volume.unit;
  }
  metadata.structure["kind"] = "octree";
  metadata.structure["lossless"] = built.lossless;
  metadata.structure["source_encoding"] = sample_type_name(volume.type);
  metadata.structure["max_abs_error"] = built.max_abs_error;
  if (options.keep) {
    metadata.structure["keep"] = {
        {"rule", "threshold"}, {"threshold", report.threshold}, {"margin", options.keep->margin}};
    if (options.keep->otsu) metadata.structure["keep"]["threshold_method"] = "otsu";
  }
  WriteOptions write;
  if (options.block_bytes) write.block_bytes = options.block_bytes;
  report.file_bytes = write_octree(built.octree, metadata, path, write).file_bytes;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

SampleType natural_sample_type(const Reader& reader) {
  const VolumeLayout& v = reader.layout();
  if (v.encoding == ValueEncoding::UInt16 && v.value_scale == 1.0 && v.value_offset == 0.0) return SampleType::UInt16;
  return SampleType::Float32;
}

DenseVolume export_from_ivol(Reader& reader, Box box, unsigned lod, SampleType type) {
  if (box.empty()) box = full_box(reader.layout().dims, lod);
  const std::vector<float> values = reader.read_box(box, lod);
  DenseVolume out = make_dense(Dims{box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]}, type);
  const Metadata& m = reader.metadata();
  const double scale = std::ldexp(1.0, static_cast<int>(lod));
  out.has_geometry = true;
  out.unit = m.unit;
  for (int a = 0; a < 3; ++a) {
    out.voxel_size[a] = m.voxel_size[a] * scale;
    // Centre of the box's first cell: the centre of the 2^lod voxels it covers.
    out.origin[a] = m.origin[a] + (box.lo[a] * scale + (scale - 1) / 2) * m.voxel_size[a];
  }
  auto clamp_round = [](double v, double lo, double hi) {
    return std::isnan(v) ? 0.0 : std::min(hi, std::max(lo, std::nearbyint(v)));
  };
  for (std::uint64_t i = 0; i < values.size(); ++i) {
    std::uint8_t* p = out.data.data() + i * sample_size(type);
    switch (type) {
      case SampleType::UInt8:
        *p = static_cast<std::uint8_t>(clamp_round(values[i], 0, 255));
        break;
      case SampleType::UInt16: {
        const auto v = static_cast<std::uint16_t>(clamp_round(values[i], 0, 65535));
        std::memcpy(p, &v, 2);
        break;
      }
      case SampleType::Int16: {
        const auto v = static_cast<std::int16_t>(clamp_round(values[i], -32768, 32767));
        std::memcpy(p, &v, 2);
        break;
      }
      case SampleType::Float16: {
        const std::uint16_t v = float_to_binary16(values[i]);
        std::memcpy(p, &v, 2);
        break;
      }
      case SampleType::Float32:
        std::memcpy(p, &values[i], 4);
        break;
    }
  }
  return out;
}

}  // namespace ivol::convert
