#include "bricked_keep.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "bricked_import.hpp"
#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "sample_values.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

// The mean of the values below `threshold` (NaN aside), read `slab` slices
// at a time, summed in binary64; the threshold where none lies below.
double streamed_mean_below(SlabReader& source, std::uint32_t slab, float threshold) {
  double sum = 0.0;
  std::uint64_t count = 0;
  for_each_float_slab(source, slab, "the background's mean", [&](const float* values, std::uint64_t n) {
    for (std::uint64_t i = 0; i < n; ++i)
      if (values[i] < threshold) sum += values[i], ++count;  // false for NaN
  });
  return count ? sum / static_cast<double>(count) : threshold;
}

// The background as the grid stores it, and the value a reader returns
// for it: binary16 rounded to nearest, a uint16 code (an integer sample
// less the encoding's offset, clamped), or float32.
struct Background {
  std::uint32_t stored = 0;
  double value = 0.0;
};
Background stored_background(double mean, ValueEncoding encoding, double code_offset, double value_offset) {
  Background b;
  switch (encoding) {
    case ValueEncoding::Binary16: {
      const std::uint16_t h = float_to_binary16(static_cast<float>(mean));
      b.stored = h;
      b.value = binary16_to_float(h);
      break;
    }
    case ValueEncoding::UInt16: {
      const double code = std::clamp(std::nearbyint(mean - code_offset), 0.0, 65535.0);
      b.stored = static_cast<std::uint32_t>(code);
      b.value = value_offset + code;
      break;
    }
    case ValueEncoding::Float32: {
      const auto f = static_cast<float>(mean);
      std::memcpy(&b.stored, &f, sizeof f);
      b.value = f;
      break;
    }
  }
  return b;
}

}  // namespace

void import_bricked_keep(SlabReader& source, const std::string& path, const ImportOptions& options,
                         const StreamingOptions& streaming, ImportReport& report) {
  if (!options.keep) throw Error(ErrorClass::InvalidArgument, "import_bricked_keep: no keep rule");
  const DenseVolume& shape = source.shape();
  const KeepRule& rule = *options.keep;
  BuildOptions build = streaming.build;
  if (build.value_scale != 1.0)
    throw Error(ErrorClass::InvalidArgument,
                "--keep with --structure bricked: values with a scale (physical = offset + scale x stored) are "
                "not supported; drop --structure bricked for an octree");
  const double code_offset = sample_code_offset(options, streaming.build);
  build.value_offset = code_offset;  // what samples_to_stored subtracts
  BrickedImport writer(shape, path, options, streaming);
  const std::uint32_t layer = writer.layer_slices();
  // Slices read either side of a layer: the margin, no more than the volume
  // (the mask itself grows by the whole margin in x and y).
  const std::uint32_t margin = std::min<std::uint32_t>(rule.margin, shape.dims[2]);
  const std::string what = path + ": a layer of " + std::to_string(layer) + " slices of " +
                           std::to_string(shape.dims[0]) + "x" + std::to_string(shape.dims[1]) + " " +
                           sample_type_name(shape.type) + " and the keep rule's " + std::to_string(margin) +
                           " slices either side";
  const std::uint64_t slice = slice_voxels(shape.dims, what);
  // A layer and its margins: the samples, their float32 copy and the mask's
  // bytes, beside what the writer holds for a layer.
  const std::uint64_t read_slices = std::min<std::uint64_t>(std::uint64_t{layer} + 2ull * margin, shape.dims[2]);
  const std::uint64_t read_voxels = checked_mul(read_slices, slice, what);
  const bool samples_are_values = shape.type == SampleType::Float32;
  const std::uint64_t halo_bytes =
      checked_mul(read_voxels, sample_size(shape.type) + (samples_are_values ? 0 : 4) + 1, what);
  require_within_budget(checked_add(halo_bytes, bricked_layer_bytes(shape, options, build.encoding, layer), what),
                        bricked_layer_budget(options), what);

  BrickedKeepOutcome outcome;
  outcome.threshold = rule.otsu ? streamed_otsu(source, layer) : rule.threshold;
  const Background background = stored_background(streamed_mean_below(source, layer, outcome.threshold), build.encoding,
                                                  code_offset, streaming.build.value_offset);
  outcome.background = background.value;

  std::vector<std::uint8_t> samples;
  checked_resize(samples, read_voxels * sample_size(shape.type), what + " (samples)");
  std::vector<float> values;
  checked_resize(values, samples_are_values ? 0 : read_voxels, what + " (as float32)");
  std::vector<float> scratch;
  LossTally loss;
  auto add_layers = [&](auto stored_type) {
    using T = decltype(stored_type);
    std::vector<T> stored;
    checked_resize(stored, checked_mul(layer, slice, what), what + " (as stored values)");
    const auto outside = static_cast<T>(background.stored);
    while (writer.next_layer_count() > 0) {
      const std::uint32_t z0 = writer.next_layer_first(), n = writer.next_layer_count();
      const std::uint32_t lo = z0 >= margin ? z0 - margin : 0;
      const std::uint32_t hi = std::min(shape.dims[2], z0 + n + margin);
      source.read(lo, hi - lo, samples.data());
      const float* value_data = reinterpret_cast<const float*>(samples.data());
      if (!samples_are_values) {
        to_float(shape, samples.data(), std::uint64_t{hi - lo} * slice, values.data());
        value_data = values.data();
      }
      const std::uint64_t centre = std::uint64_t{z0 - lo} * slice, count = std::uint64_t{n} * slice;
      samples_to_stored(shape, build, samples.data() + centre * sample_size(shape.type), count, scratch, stored.data(),
                        loss);
      const std::vector<std::uint8_t> keep =
          slab_keep_mask(value_data, shape.dims, lo, hi, z0, n, outcome.threshold, rule.margin);
      for (std::uint64_t i = 0; i < count; ++i) {
        if (keep[i]) {
          ++outcome.kept;
          continue;
        }
        const float v = value_data[centre + i];
        if (std::isnan(v))
          ++outcome.nans_replaced;
        else
          outcome.max_abs_error = std::max(outcome.max_abs_error, std::fabs(static_cast<double>(v) - background.value));
        ++outcome.replaced;
        stored[i] = outside;
      }
      writer.add_layer(stored.data());
      if (options.progress) options.progress(z0 + n, shape.dims[2]);
    }
  };
  with_stored_type(build.encoding, add_layers);
  writer.finish(loss, report, &outcome);
}

}  // namespace ivol::convert
