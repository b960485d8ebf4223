#include "ivol_io.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <thread>

#include "bricked_import.hpp"
#include "bricked_keep.hpp"
#include "disk_space.hpp"
#include "ivol/binary16.hpp"
#include "ivol/bricked_writer.hpp"
#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/geometry.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/writer.hpp"
#include "ivol_source.hpp"
#include "sample_values.hpp"
#include "sizes.hpp"

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

void for_each_float_slab(SlabReader& source, std::uint32_t slab, const std::string& what,
                         const std::function<void(const float*, std::uint64_t)>& visit) {
  const DenseVolume& shape = source.shape();
  const std::uint64_t slice = slice_voxels(shape.dims, what);
  const std::uint64_t held = std::uint64_t{std::min(slab, shape.dims[2])} * slice;
  std::vector<std::uint8_t> samples;
  checked_resize(samples, held * sample_size(shape.type), what + ": a slab of samples");
  std::vector<float> values;
  checked_resize(values, held, what + ": a slab as float32");
  for (std::uint32_t z = 0; z < shape.dims[2]; z += slab) {
    const std::uint32_t n = std::min(slab, shape.dims[2] - z);
    source.read(z, n, samples.data());
    to_float(shape, samples.data(), n * slice, values.data());
    visit(values.data(), n * slice);
  }
}

float streamed_otsu(SlabReader& source, std::uint32_t slab) {
  double lo = INFINITY, hi = -INFINITY;
  for_each_float_slab(source, slab, "Otsu's threshold", [&](const float* values, std::uint64_t count) {
    for (std::uint64_t i = 0; i < count; ++i)
      if (!std::isnan(values[i])) lo = std::min<double>(lo, values[i]), hi = std::max<double>(hi, values[i]);
  });
  if (!(hi > lo)) return static_cast<float>(lo);
  std::vector<double> histogram(256, 0.0);
  const double scale = histogram.size() / (hi - lo);
  for_each_float_slab(source, slab, "Otsu's threshold", [&](const float* values, std::uint64_t count) {
    for (std::uint64_t i = 0; i < count; ++i)
      if (!std::isnan(values[i]))
        histogram[std::min<std::size_t>(histogram.size() - 1, static_cast<std::size_t>((values[i] - lo) * scale))] += 1;
  });
  return otsu_threshold_from_histogram(histogram, lo, hi);
}

namespace {

// Integer samples as the uint16 encoding's codes (sample - offset).
// Bytes per voxel of a slab that the streaming writer holds besides the
// samples given to it (its stored values and the subtrees it builds): about
// 2 measured on a 16384^2 uint16 slice (1.39 GB peak in all); 4 leaves room.
constexpr std::uint64_t kWriterBytesPerVoxel = 4;

class ProgressTicker {
 public:
  ProgressTicker(const Progress& progress, std::uint64_t total) : progress_(progress), total_(total) {}
  void update(std::uint64_t done) {
    if (!progress_) return;
    const auto now = std::chrono::steady_clock::now();
    if (done < total_ && now - last_ < std::chrono::milliseconds(250)) return;
    last_ = now;
    progress_(done, total_);
  }

 private:
  const Progress& progress_;
  std::uint64_t total_;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace

StreamingOptions import_streaming_options(const DenseVolume& shape, const ImportOptions& options,
                                          ImportReport& report) {
  report.encoding = options.encoding.value_or(lossless_encoding(shape.type));
  StreamingOptions streaming;
  BuildOptions& build = streaming.build;
  build.encoding = report.encoding;
  const bool integer_source =
      shape.type == SampleType::UInt8 || shape.type == SampleType::UInt16 || shape.type == SampleType::Int16;
  if (build.encoding == ValueEncoding::UInt16 && !integer_source)
    throw Error(ErrorClass::InvalidArgument,
                std::string("--encoding uint16 needs integer samples; this volume holds ") +
                    sample_type_name(shape.type) + " (use binary16 or float32)");
  if (build.encoding == ValueEncoding::UInt16 && shape.type == SampleType::Int16) build.value_offset = -32768.0;
  if (options.stored_values) {
    // An .ivol input's values: the same encoding keeps them as they are,
    // with the input's scale and offset. Another encoding or a keep rule
    // works on the samples' own numbers, which are the physical values only
    // where the scale is 1 and the offset 0.
    const bool same_encoding = build.encoding == lossless_encoding(shape.type);
    const bool identity = options.stored_values->scale == 1.0 && options.stored_values->offset == 0.0;
    if (!identity && !same_encoding)
      throw Error(ErrorClass::InvalidArgument,
                  std::string("--encoding ") + encoding_name(build.encoding) +
                      ": an .ivol input whose values have a scale or offset (physical = offset + scale x stored) is "
                      "re-encoded as it is stored (" +
                      encoding_name(lossless_encoding(shape.type)) + "); export it first to change the encoding");
    if (!identity && options.keep)
      throw Error(ErrorClass::InvalidArgument,
                  "--keep: an .ivol input whose values have a scale or offset (physical = offset + scale x stored) "
                  "takes no keep rule here; export it first to coarsen it");
    // The octree and grid writers take float samples as physical values:
    // stored values of binary16 or float32 under a scale would be scaled again.
    if (!identity && build.encoding != ValueEncoding::UInt16)
      throw Error(ErrorClass::InvalidArgument,
                  std::string("an .ivol input of ") + encoding_name(build.encoding) +
                      " values with a scale or offset cannot be re-encoded as it is stored; export it first");
    if (same_encoding) {
      build.value_scale = options.stored_values->scale;
      build.value_offset = options.stored_values->offset;
    }
  }
  report.value_scale = build.value_scale;
  report.value_offset = build.value_offset;
  if (options.block_bytes) streaming.write.block_bytes = options.block_bytes;
  streaming.write.byte_planes = options.byte_planes;
  streaming.write.zstd_level = options.zstd_level;
  streaming.write.framed_blocks = options.framed_blocks;
  streaming.write.encoder = options.encoder;
  if (options.slab_budget_bytes) streaming.slab_budget_bytes = options.slab_budget_bytes;
  streaming.spill_directory = options.temp_directory;
  return streaming;
}

std::vector<std::uint8_t> slab_keep_mask(const float* values, const Dims& dims, std::uint32_t lo, std::uint32_t hi,
                                         std::uint32_t z0, std::uint32_t count, float threshold, unsigned margin) {
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  std::vector<std::uint8_t> keep = threshold_keep_mask(values, Dims{dims[0], dims[1], hi - lo}, threshold, margin);
  keep.erase(keep.begin(), keep.begin() + static_cast<std::ptrdiff_t>((z0 - lo) * slice));
  keep.resize(count * slice);
  return keep;
}

void refuse_encoding_loss(const LossTally& loss, const DenseVolume& shape, const ImportOptions& options,
                          const std::string& path, ValueEncoding encoding) {
  if (options.allow_lossy) return;
  refuse_loss(loss, shape.voxel_count(),
              (options.what.empty() ? path : options.what) + ": " + sample_type_name(shape.type) + " samples as " +
                  encoding_name(encoding),
              encoding_name(encoding), "--encoding " + std::string(encoding_name(lossless_encoding(shape.type))));
}

Metadata import_metadata(const DenseVolume& shape, const ImportOptions& options) {
  Metadata metadata = options.metadata;
  if (options.complete_metadata) options.complete_metadata(metadata);
  if (shape.has_geometry) {
    metadata.voxel_size = shape.voxel_size;
    metadata.origin = shape.origin;
    metadata.unit = shape.unit;
  }
  return metadata;
}

double sample_code_offset(const ImportOptions& options, const BuildOptions& build) {
  return options.stored_values ? 0.0 : build.value_offset;
}

void finish_import(StreamingOctreeWriter& writer, const DenseVolume& shape, const ImportOptions& options,
                   ImportReport& report) {
  Metadata metadata = import_metadata(shape, options);
  // The outcome of the build is known only at the end; finish() writes the
  // metadata after the blocks, so say it here from what the slabs reported.
  metadata.structure["kind"] = "octree";
  if (!report.structure_reason.empty()) metadata.structure["chosen_because"] = report.structure_reason;
  metadata.structure["source_encoding"] = sample_type_name(shape.type);
  if (options.keep) {
    metadata.structure["keep"] = {
        {"rule", "threshold"}, {"threshold", report.threshold}, {"margin", options.keep->margin}};
    if (options.keep->otsu) metadata.structure["keep"]["threshold_method"] = "otsu";
  }
  const StreamingResult result = writer.finish(metadata, [&](Metadata& m, const StreamingResult& r) {
    m.structure["lossless"] = r.lossless;
    m.structure["max_abs_error"] = r.max_abs_error;
    inherit_structure(m, options.input_structure);
  });
  report.lossless = result.lossless;
  report.max_abs_error = result.max_abs_error;
  report.kept_voxels = result.kept_voxels;
  report.file_bytes = result.write.file_bytes;
  report.temp_bytes = result.spill_bytes;
  report.temp_directory = result.spill_directory;
}

namespace {

// The smallest --memory under which the octree import's slabs fit. Where the
// slab budget is a quarter of --memory (the CLI's rule), more memory may
// choose thicker slabs, which need more: iterate to the fixed point, with
// the writer's rule for the thickness (slab_subtrees.hpp, choose_slab_slices).
std::uint64_t memory_that_would_do(const Dims& dims, const ImportOptions& options, std::uint64_t needed,
                                   const std::function<std::uint64_t(std::uint32_t)>& needed_for) {
  if (options.slab_budget_bytes == 0 || options.slab_budget_bytes != memory_budget(options.memory_bytes) / 4)
    return needed;
  const std::uint32_t side = 1u << depth_for(dims);
  std::uint64_t slice_bytes = 0, bytes = 0;
  if (__builtin_mul_overflow(std::uint64_t{dims[0]} * dims[1], 4u, &slice_bytes)) return needed;
  std::uint64_t memory = needed;
  for (int step = 0; step < 64; ++step) {
    std::uint32_t slices = 8;
    while (slices < side && !__builtin_mul_overflow(std::uint64_t{2} * slices, slice_bytes, &bytes) &&
           bytes <= memory / 4)
      slices *= 2;
    const std::uint64_t more = needed_for(std::min(slices, side));
    if (more <= memory) break;
    memory = more;
  }
  return memory;
}

// The bricked regular grid, a layer of bricks at a time, its samples read
// as many slices at once as the layer's budget allows (bricked_read_slices):
// whole layers, or parts of one. Where the budget holds a second layer
// (bricked_prefetch), the next layer is read on a thread of its own while
// this one is encoded: reading and turning samples into stored values
// were a core's work that the encoders waited for. T: the stored values'
// type (with_stored_type).
template <class T>
void import_bricked(SlabReader& source, const std::string& path, const ImportOptions& options,
                    const StreamingOptions& streaming, ImportReport& report) {
  const DenseVolume& shape = source.shape();
  BuildOptions build = streaming.build;
  BrickedImport writer(shape, path, options, streaming);
  build.value_offset = sample_code_offset(options, streaming.build);  // what samples_to_stored subtracts
  const std::uint32_t layer = writer.layer_slices();
  const std::uint32_t read = bricked_read_slices(shape, options, build.encoding, source.thick_reads_pay());
  const std::string what = path + ": a layer of " + std::to_string(layer) + " slices of " +
                           std::to_string(shape.dims[0]) + "x" + std::to_string(shape.dims[1]) + " " +
                           sample_type_name(shape.type);
  require_within_budget(bricked_layer_bytes(shape, options, build.encoding, std::max(read, 1u)),
                        bricked_layer_budget(options), what);
  const std::uint64_t slice = slice_voxels(shape.dims, what);
  // What one layer is read into: the samples, their float32 copy, the
  // stored values.
  struct Buffers {
    std::vector<std::uint8_t> samples;
    std::vector<float> scratch;
    std::vector<T> stored;
  };
  const bool as_read = stored_as_read(shape, build);
  auto allocate = [&](Buffers& b) {
    if (!as_read)
      checked_resize(b.samples, checked_mul(checked_mul(read, slice, what), sample_size(shape.type), what),
                     what + " (samples)");
    checked_resize(b.stored, checked_mul(std::max(layer, read), slice, what), what + " (as stored values)");
  };
  Buffers current;
  allocate(current);
  LossTally loss;
  // Read into b.stored itself where its bytes are the samples'.
  auto read_into = [&](Buffers& b, std::uint32_t z0, std::uint32_t count, std::uint64_t at) {
    if (as_read) return source.read(z0, count, reinterpret_cast<std::uint8_t*>(b.stored.data() + at));
    source.read(z0, count, b.samples.data());
    samples_to_stored(shape, build, b.samples.data(), std::uint64_t{count} * slice, b.scratch, b.stored.data() + at,
                      loss);
  };
  ProgressTicker ticker(options.progress, shape.dims[2]);
  if (read > layer) {  // whole layers at a time
    while (writer.next_layer_count() > 0) {
      const std::uint32_t z0 = writer.next_layer_first();
      const std::uint32_t count = std::min(read, shape.dims[2] - z0);
      read_into(current, z0, count, 0);
      for (std::uint32_t done = 0; done < count;) {
        const std::uint32_t next = writer.next_layer_count();
        writer.add_layer(current.stored.data() + std::uint64_t{done} * slice);
        done += next;
        ticker.update(z0 + done);
      }
    }
    writer.finish(loss, report);
    return;
  }
  // The layer of slices z0 .. z0 + n into b, `read` slices at a time.
  auto fill = [&](Buffers& b, std::uint32_t z0, std::uint32_t n) {
    for (std::uint32_t z = 0; z < n; z += read) {
      const std::uint32_t count = std::min(read, n - z);
      read_into(b, z0 + z, count, std::uint64_t{z} * slice);
    }
  };
  const bool prefetch = bricked_prefetch(shape, options, build.encoding, read);
  Buffers next;
  if (prefetch) allocate(next);
  std::uint32_t z0 = writer.next_layer_first(), n = writer.next_layer_count();
  fill(current, z0, n);
  while (n > 0) {
    const std::uint32_t next_z0 = z0 + n;
    const std::uint32_t next_n = next_z0 < shape.dims[2] ? std::min(layer, shape.dims[2] - next_z0) : 0;
    std::thread reader;
    std::exception_ptr read_failure;
    if (prefetch && next_n > 0)
      reader = std::thread([&] {
        try {
          fill(next, next_z0, next_n);
        } catch (...) {
          read_failure = std::current_exception();
        }
      });
    try {
      writer.add_layer(current.stored.data());
    } catch (...) {
      if (reader.joinable()) reader.join();
      throw;
    }
    if (reader.joinable()) reader.join();
    if (read_failure) std::rethrow_exception(read_failure);
    ticker.update(next_z0);
    if (writer.next_layer_count() != next_n || (next_n > 0 && writer.next_layer_first() != next_z0))
      throw Error(ErrorClass::Io, what + ": the writer's next layer is not the one read");
    if (next_n > 0) {
      if (prefetch)
        std::swap(current, next);
      else
        fill(current, next_z0, next_n);
    }
    z0 = next_z0, n = next_n;
  }
  writer.finish(loss, report);
}

}  // namespace

ImportReport import_to_ivol(SlabReader& source, const std::string& path, const ImportOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const DenseVolume& shape = source.shape();
  ImportReport report;
  const StreamingOptions streaming = import_streaming_options(shape, options, report);
  const BuildOptions& build = streaming.build;
  const bool codes = build.encoding == ValueEncoding::UInt16;
  const bool bricked = choose_bricked(shape, options, build.encoding, report);
  if (options.check_disk_space)
    require_disk_space(ivol_disk_needs(shape.dims, build.encoding, !bricked, path, options.temp_directory));
  if (bricked && options.keep) {
    import_bricked_keep(source, path, options, streaming, report);
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return report;
  }
  if (bricked) {
    with_stored_type(build.encoding,
                     [&](auto t) { import_bricked<decltype(t)>(source, path, options, streaming, report); });
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return report;
  }

  StreamingOctreeWriter writer(path, shape.dims, streaming);
  const std::uint32_t slab = writer.slab_slices();
  report.slab_slices = slab;
  const unsigned margin = options.keep ? options.keep->margin : 0;

  // One slab and the `margin` slices on either side, which the keep mask's
  // growth needs. The writer takes slabs of at least 8 slices whatever
  // their size, so a huge slice (a 16384^2 TIFF page of a few hundred KB
  // of deflate) is weighed against the budget before anything is read.
  const std::string what = path + ": a slab of " + std::to_string(std::min(slab, shape.dims[2])) + " slices of " +
                           std::to_string(shape.dims[0]) + "x" + std::to_string(shape.dims[1]) + " " +
                           sample_type_name(shape.type);
  const std::uint64_t slice = slice_voxels(shape.dims, what);
  const bool need_values = !codes || options.keep;
  // float32 samples are their own float32 values: no second copy (at 2048³
  // from recon, 512 MiB that the budget did not count).
  const bool samples_are_values = shape.type == SampleType::Float32;
  const bool copy_values = need_values && !samples_are_values;
  // What slabs of `slices` hold: samples (and floats, and the keep mask)
  // with their margins, the codes and the writer's own share.
  const auto needed_for = [&](std::uint32_t slices) {
    const std::uint64_t most =
        checked_mul(std::min<std::uint64_t>(std::uint64_t{slices} + 2ull * margin, shape.dims[2]), slice, what);
    const std::uint64_t slab_voxels = checked_mul(std::min(slices, shape.dims[2]), slice, what);
    const std::uint64_t held =
        checked_mul(most, sample_size(shape.type) + (copy_values ? 4 : 0) + (options.keep ? 1 : 0), what);
    return checked_add(held, checked_mul(slab_voxels, (codes ? 2 : 0) + kWriterBytesPerVoxel, what), what);
  };
  const std::uint64_t most =
      checked_mul(std::min<std::uint64_t>(std::uint64_t{slab} + 2ull * margin, shape.dims[2]), slice, what);
  const std::uint64_t slab_voxels = checked_mul(std::min(slab, shape.dims[2]), slice, what);
  const std::uint64_t needed = needed_for(slab);
  if (needed > memory_budget(options.memory_bytes))
    throw Error(ErrorClass::LimitExceeded,
                what + " needs " + mib_text(needed) + ", more than the " +
                    mib_text(memory_budget(options.memory_bytes)) +
                    " this conversion may hold: the .ivol writer takes whole slices, 8 or more at a time (" +
                    memory_option_for(memory_that_would_do(shape.dims, options, needed, needed_for)) + " allows it)");
  if (options.keep) report.threshold = options.keep->otsu ? streamed_otsu(source, slab) : options.keep->threshold;
  std::vector<std::uint8_t> samples;
  checked_resize(samples, most * sample_size(shape.type), what + " (samples)");
  std::vector<float> values;
  checked_resize(values, copy_values ? most : 0, what + " (as float32)");
  const float* value_data = samples_are_values ? reinterpret_cast<const float*>(samples.data()) : values.data();
  std::vector<std::uint16_t> code_values;
  checked_resize(code_values, codes ? slab_voxels : 0, what + " (as uint16 codes)");
  ProgressTicker ticker(options.progress, shape.dims[2]);
  while (writer.next_slab_count() > 0) {
    const std::uint32_t z0 = writer.next_slab_first();
    const std::uint32_t n = writer.next_slab_count();
    const std::uint32_t lo = z0 >= margin ? z0 - margin : 0;
    const std::uint32_t hi = std::min(shape.dims[2], z0 + n + margin);
    source.read(lo, hi - lo, samples.data());
    const std::uint64_t centre = (z0 - lo) * slice;
    if (copy_values) to_float(shape, samples.data(), (hi - lo) * slice, values.data());
    std::vector<std::uint8_t> keep;
    if (options.keep) keep = slab_keep_mask(value_data, shape.dims, lo, hi, z0, n, report.threshold, margin);
    if (codes) {
      to_codes(shape.type, samples.data() + centre * sample_size(shape.type), n * slice,
               sample_code_offset(options, build), code_values.data());
      writer.add_slab(code_values.data(), options.keep ? keep.data() : nullptr);
    } else {
      tally_encoding(build.encoding, value_data + centre, n * slice, report.encoding_loss);
      writer.add_slab(value_data + centre, options.keep ? keep.data() : nullptr);
    }
    ticker.update(z0 + n);
  }
  refuse_encoding_loss(report.encoding_loss, shape, options, path, build.encoding);
  finish_import(writer, shape, options, report);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

ImportReport import_to_ivol(const DenseVolume& volume, const std::string& path, const ImportOptions& options) {
  const auto source = view_slabs(volume);
  return import_to_ivol(*source, path, options);
}

SampleType natural_sample_type(const Reader& reader) {
  const VolumeLayout& v = reader.layout();
  const bool identity = v.value_scale == 1.0 && v.value_offset == 0.0;
  const auto source = reader.metadata().structure.find("source_encoding");
  const std::string source_type =
      source != reader.metadata().structure.end() && source->is_string() ? source->get<std::string>() : "";
  if (v.encoding == ValueEncoding::UInt16) {
    if (identity && source_type == "u8") return SampleType::UInt8;
    const double lo = std::min(v.physical(0), v.physical(65535)), hi = std::max(v.physical(0), v.physical(65535));
    const bool integers =
        std::nearbyint(v.value_scale) == v.value_scale && std::nearbyint(v.value_offset) == v.value_offset;
    if (integers && lo >= 0 && hi <= 65535) return SampleType::UInt16;
    if (integers && lo >= -32768 && hi <= 32767) return SampleType::Int16;
  }
  if (v.encoding == ValueEncoding::Binary16 && identity && source_type == "f16") return SampleType::Float16;
  return SampleType::Float32;
}

SampleType natural_float_type(const Reader& reader) {
  const VolumeLayout& v = reader.layout();
  const bool identity = v.value_scale == 1.0 && v.value_offset == 0.0;
  return v.encoding == ValueEncoding::Binary16 && identity ? SampleType::Float16 : SampleType::Float32;
}

DenseVolume export_shape(const Reader& reader, const Box& box, unsigned lod, SampleType type) {
  DenseVolume out;
  out.dims = Dims{box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]};
  out.type = type;
  const Metadata& m = reader.metadata();
  const double scale = std::ldexp(1.0, static_cast<int>(lod));
  // A salvaged file whose metadata was lost has the defaults' voxel size,
  // not its own: the export says nothing rather than 1 a voxel.
  const bool metadata_lost = !reader.metadata_problem().empty();
  out.has_geometry =
      !metadata_lost && !(m.provenance.contains("voxel_size_known") && m.provenance["voxel_size_known"] == false);
  out.unit = m.unit;
  out.voxel_size_from = out.origin_from = out.unit_from = "the .ivol metadata";
  out.quantity = m.quantity;
  out.quantity_from = "the .ivol metadata";
  out.value_unit = m.value_unit;
  if (!m.provenance.empty()) out.provenance = m.provenance.dump();
  for (int a = 0; a < 3; ++a) {
    out.voxel_size[a] = m.voxel_size[a] * scale;
    // Centre of the box's first cell: the centre of the 2^lod voxels it covers.
    out.origin[a] = m.origin[a] + (box.lo[a] * scale + (scale - 1) / 2) * m.voxel_size[a];
  }
  return out;
}

namespace {

class MemorySink final : public SlabWriter {
 public:
  explicit MemorySink(DenseVolume& volume) : volume_(volume) {}
  void write(const void* samples, std::uint32_t count) override {
    const std::uint64_t bytes = slab_bytes(volume_.dims, count, volume_.type, "an exported volume");
    std::memcpy(volume_.data.data() + at_, samples, bytes);
    at_ += bytes;
  }
  void finish() override {}

 private:
  DenseVolume& volume_;
  std::size_t at_ = 0;
};

}  // namespace

LossTally export_from_ivol(Reader& reader, Box box, unsigned lod, SampleType type, SlabWriter& sink,
                           const Progress& progress, std::vector<DamagedRegion>* damaged, const LossCheck& check,
                           std::uint64_t memory_bytes) {
  if (box.empty()) box = full_box(reader.layout().dims, lod);
  const std::uint64_t budget = memory_budget(memory_bytes);
  // Slabs of about 64 MiB of float32 (less under a smaller budget), whole
  // slices; a slice that alone exceeds the budget (a one-leaf file of 2^31
  // per side) is refused.
  const Dims box_dims{box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]};
  const std::string what =
      "exporting " + dims_text(box_dims) + " voxels at level " + std::to_string(lod) + ": one slice";
  // Weighed in floating point first: a slice of 2^31 x 2^31 float32 values
  // is 2^64 bytes, which the checked products below cannot even state.
  require_within_budget(voxel_count_approx(Dims{box_dims[0], box_dims[1], 1}) * (4.0 + sample_size(type)), budget,
                        what + " as float32 and " + sample_type_name(type));
  const std::uint64_t slice = slice_voxels(box_dims, what);
  const std::uint64_t slice_bytes = checked_mul(slice, 4 + sample_size(type), what);
  require_within_budget(slice_bytes, budget, what + " as float32 and " + sample_type_name(type));
  // What the sink holds for the whole run (an OpenVDB output's volume and
  // tree, which it weighed with one slice) leaves the rest for slabs.
  const std::uint64_t left = budget > sink.held_bytes() ? budget - sink.held_bytes() : 0;
  const auto slab =
      static_cast<std::uint32_t>(std::max<std::uint64_t>(1, std::min<std::uint64_t>(64ull << 20, left) / slice_bytes));
  ProgressTicker ticker(progress, box.hi[2] - box.lo[2]);
  std::vector<std::uint8_t> samples;
  LossTally loss;
  // Stored bits, not Reader::read_box's float32 physical values: those lose
  // the payload of a signalling NaN and cannot say what a uint16 code with a
  // scale and an offset means exactly.
  for (std::uint32_t z = box.lo[2]; z < box.hi[2]; z += slab) {
    Box part = box;
    part.lo[2] = z;
    part.hi[2] = std::min(box.hi[2], z + slab);
    const std::vector<std::uint8_t> stored = reader.read_box_bits(part, lod, damaged);
    const std::uint64_t count = stored.size() / encoding_width(reader.layout().encoding);
    samples.resize(count * sample_size(type));
    stored_to_samples(reader.layout(), stored.data(), count, type, samples.data(), loss);
    sink.write(samples.data(), part.hi[2] - part.lo[2]);
    ticker.update(part.hi[2] - box.lo[2]);
  }
  if (check) check(loss, slice * (box.hi[2] - box.lo[2]));
  sink.finish();
  return loss;
}

DenseVolume export_from_ivol(Reader& reader, Box box, unsigned lod, SampleType type) {
  if (box.empty()) box = full_box(reader.layout().dims, lod);
  DenseVolume out = export_shape(reader, box, lod, type);
  checked_resize(out.data, slab_bytes(out.dims, out.dims[2], type, "an exported volume"),
                 "exporting " + dims_text(out.dims) + " voxels into memory");
  MemorySink sink(out);
  export_from_ivol(reader, box, lod, type, sink);
  return out;
}

}  // namespace ivol::convert
