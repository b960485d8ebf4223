#include "ivol/recon/preview.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "host_spool.hpp"
#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"

namespace ivol::recon {
namespace {

bool is_power_of_two(unsigned n) { return n != 0 && (n & (n - 1)) == 0; }

// `full` coarsened `factor` times: each voxel covers factor³ full voxels,
// centred on them.
VolumeGrid coarsened(const VolumeGrid& full, unsigned factor) {
  VolumeGrid coarse;
  for (int a = 0; a < 3; ++a) {
    coarse.size[a] = (full.size[a] + factor - 1) / factor;
    coarse.voxel_size[a] = full.voxel_size[a] * factor;
    coarse.origin[a] = full.origin[a] + 0.5 * (factor - 1) * full.voxel_size[a];
  }
  return coarse;
}

// Every view_step-th view, bin² pixels merged: `thinning` each, less where
// that would leave too few pixels or views (a small scan).
std::pair<unsigned, unsigned> thinned_steps(const ScanGeometry& geometry, unsigned thinning) {
  unsigned bin = thinning;
  while (bin > 1 && (geometry.detector.columns / static_cast<int>(bin) < 16 ||
                     geometry.detector.rows / static_cast<int>(bin) < 16))
    bin /= 2;
  unsigned view_step = thinning;
  while (view_step > 1 && geometry.view_count() / view_step < 32) view_step /= 2;
  return {view_step, bin};
}

// FDK of `grid` from every `thinning`-th view with thinning² pixels merged
// (fewer where the scan is small); each z-slice goes to `slice` in order, on
// rank 0 only when distributed.
void reconstruct_thinned(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                         const VolumeGrid& grid, unsigned thinning,
                         const std::function<void(std::uint32_t k, const float* values)>& slice) {
  const auto [view_step, bin] = thinned_steps(geometry, thinning);
  ReducedProjections reduced(projections, view_step, bin);
  const ScanGeometry reduced_geometry = reduce_scan(geometry, view_step, bin);
  FdkReconstructor reconstructor(reduced, reduced_geometry, options);
  const std::size_t area = std::size_t{grid.size[0]} * grid.size[1];
  reconstructor.reconstruct(grid, [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
    for (std::uint32_t k = k0; k < k1; ++k) slice(k, data + (k - k0) * area);
  });
}

// Distributed, only rank 0 received the preview; every rank needs it to
// generate the same structure.
void share(const FdkOptions& options, std::vector<float>& values) {
  if (options.exchange && options.exchange->size() > 1) options.exchange->broadcast(values);
}

// Largest value within `reach` places along one axis of a line of `n`
// values `stride` apart, every `ratio`-th place kept: out[c] = max of in over
// [ratio·c − reach, ratio·c + ratio − 1 + reach].
void pool_line(const float* in, std::size_t n, std::size_t stride, unsigned ratio, unsigned reach, float* out,
               std::size_t out_n, std::size_t out_stride) {
  for (std::size_t c = 0; c < out_n; ++c) {
    const std::size_t lo = ratio * c >= reach ? ratio * c - reach : 0;
    const std::size_t hi = std::min(n, ratio * c + ratio + reach);
    float best = -std::numeric_limits<float>::infinity();
    for (std::size_t s = lo; s < hi; ++s) best = std::max(best, in[s * stride]);
    out[c * out_stride] = best;
  }
}

// A cell's value as the detection rule compares it: its largest sample
// rounded up to binary16. Rounding up never drops a cell the float would
// keep, and it halves what waits for Otsu's threshold (issue 23).
std::uint16_t cell_bits(float largest) { return float_to_binary16_upward(largest); }
float cell_value(float largest) { return binary16_to_float(cell_bits(largest)); }

void check_factor(unsigned factor, unsigned smallest) {
  if (factor < smallest || !is_power_of_two(factor))
    throw std::invalid_argument("preview: the factor must be a power of two, at least " + std::to_string(smallest));
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

Preview reconstruct_preview(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                            const VolumeGrid& full, unsigned factor) {
  check_factor(factor, 2);
  const auto start = std::chrono::steady_clock::now();
  Preview preview;
  preview.grid = coarsened(full, factor);
  preview.values.resize(preview.grid.voxel_count());
  const std::size_t area = std::size_t{preview.grid.size[0]} * preview.grid.size[1];
  reconstruct_thinned(projections, geometry, options, preview.grid, std::max(1U, factor / 2),
                      [&](std::uint32_t k, const float* values) {
                        std::copy(values, values + area,
                                  preview.values.begin() + static_cast<std::ptrdiff_t>(k * area));
                      });
  share(options, preview.values);
  preview.otsu_threshold = otsu_threshold(preview.values.data(), preview.values.size());
  preview.seconds = seconds_since(start);
  return preview;
}

Preview reconstruct_detection_preview(ProjectionSource& projections, const ScanGeometry& geometry,
                                      const FdkOptions& options, const VolumeGrid& full, unsigned factor,
                                      unsigned thinning, unsigned margin_voxels) {
  check_factor(factor, 2);
  if (thinning == 0 || !is_power_of_two(thinning))
    throw std::invalid_argument("detection preview: the thinning must be a power of two");
  const auto start = std::chrono::steady_clock::now();
  const unsigned ratio = factor > 2 ? 2 : 1;  // samples per cell and axis
  const unsigned spacing = factor / ratio;
  const unsigned reach = (margin_voxels + spacing - 1) / spacing;
  const VolumeGrid samples = coarsened(full, spacing);
  Preview preview;
  preview.grid = coarsened(full, factor);
  const std::size_t sx = samples.size[0], sy = samples.size[1], sz = samples.size[2];
  const std::size_t cx = preview.grid.size[0], cy = preview.grid.size[1], cz = preview.grid.size[2];
  // Slices of samples pooled along x and y as they arrive (a quarter of
  // each), so that the samples themselves are never all held; one sample in
  // eight is kept for Otsu's threshold.
  std::vector<float> pooled_xy(cx * cy * sz, -std::numeric_limits<float>::infinity());
  std::vector<float> otsu_samples;
  otsu_samples.reserve(((sx + 1) / 2) * ((sy + 1) / 2) * ((sz + 1) / 2));
  std::vector<float> along_x(cx * sy);
  reconstruct_thinned(projections, geometry, options, samples, thinning, [&](std::uint32_t k, const float* values) {
    for (std::size_t j = 0; j < sy; ++j) pool_line(values + j * sx, sx, 1, ratio, reach, &along_x[j * cx], cx, 1);
    for (std::size_t i = 0; i < cx; ++i)
      pool_line(&along_x[i], sy, cx, ratio, reach, &pooled_xy[k * cx * cy + i], cy, cx);
    if (k % 2 == 0)
      for (std::size_t j = 0; j < sy; j += 2)
        for (std::size_t i = 0; i < sx; i += 2) otsu_samples.push_back(values[j * sx + i]);
  });
  share(options, pooled_xy);
  share(options, otsu_samples);
  preview.values.resize(cx * cy * cz);
  for (std::size_t j = 0; j < cy; ++j)
    for (std::size_t i = 0; i < cx; ++i)
      pool_line(&pooled_xy[j * cx + i], sz, cx * cy, ratio, reach, &preview.values[j * cx + i], cz, cx * cy);
  for (float& cell : preview.values) cell = cell_value(cell);
  // Otsu's threshold of the samples, not of the maxima: the samples are a
  // reconstruction of the object, whose histogram the maxima would bias.
  preview.otsu_threshold = otsu_threshold(otsu_samples.data(), otsu_samples.size());
  preview.seconds = seconds_since(start);
  return preview;
}

namespace {

// The detection preview's shapes: samples at 1/spacing, `ratio` of them per
// cell and axis, each cell the largest sample within `reach` samples of it.
struct DetectionShape {
  unsigned ratio = 1, spacing = 1, reach = 0;
  VolumeGrid samples, cells;
  std::size_t ring_layers = 0;      // slices pooled along x and y, held at once
  std::size_t otsu_row_floats = 0;  // one sample in eight of an even slice
};

DetectionShape detection_shape(const VolumeGrid& full, const DetectionMaskOptions& detection) {
  const DetectionRule& rule = detection.rule;
  check_factor(rule.factor, 2);
  if (rule.thinning == 0 || !is_power_of_two(rule.thinning))
    throw std::invalid_argument("detection preview: the thinning must be a power of two");
  DetectionShape shape;
  shape.ratio = rule.factor > 2 ? 2 : 1;
  shape.spacing = rule.factor / shape.ratio;
  shape.reach = (detection.margin_voxels + shape.spacing - 1) / shape.spacing;
  shape.samples = coarsened(full, shape.spacing);
  shape.cells = coarsened(full, rule.factor);
  shape.ring_layers = shape.ratio + 2 * shape.reach + 1;
  shape.otsu_row_floats = ((shape.samples.size[0] + 1) / 2) * ((shape.samples.size[1] + 1) / 2);
  return shape;
}

std::uint64_t packed_mask_bytes(const VolumeGrid& cells) { return (cells.voxel_count() + 63) / 64 * 8; }

}  // namespace

std::uint64_t detection_fixed_bytes(const VolumeGrid& full, const DetectionMaskOptions& detection) {
  const DetectionShape shape = detection_shape(full, detection);
  const std::uint64_t area = std::uint64_t{shape.cells.size[0]} * shape.cells.size[1];
  const std::uint64_t floats = shape.ring_layers * area + std::uint64_t{shape.cells.size[0]} * shape.samples.size[1] +
                               area + shape.otsu_row_floats;
  return floats * sizeof(float) + area * sizeof(std::uint16_t) + packed_mask_bytes(shape.cells);
}

std::uint64_t detection_temp_bytes(const ScanGeometry& geometry, const FdkOptions& options, const VolumeGrid& full,
                                   const DetectionMaskOptions& detection) {
  const DetectionShape shape = detection_shape(full, detection);
  const std::uint64_t fixed = detection_fixed_bytes(full, detection);
  // As they are: the spool stores a record compressed only where that is smaller.
  const std::uint64_t records =
      shape.cells.voxel_count() * sizeof(std::uint16_t) +
      shape.otsu_row_floats * ((std::uint64_t{shape.samples.size[2]} + 1) / 2) * sizeof(float);
  const std::uint64_t room = detection.preview_memory > fixed ? detection.preview_memory - fixed : 0;
  const auto [view_step, bin] = thinned_steps(geometry, detection.rule.thinning);
  return (records > room ? records - room : 0) +
         filtered_rows_disk_bound(reduce_scan(geometry, view_step, bin), options);
}

DetectionMask detect_need_mask(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                               const VolumeGrid& full, const DetectionMaskOptions& detection) {
  const DetectionShape shape = detection_shape(full, detection);
  // The buffers below and the packed mask are held whatever the budget;
  // refused before any work when the budget cannot hold them.
  const std::uint64_t fixed_bytes = detection_fixed_bytes(full, detection);
  if (detection.preview_memory < fixed_bytes)
    throw Error(
        ErrorClass::LimitExceeded,
        "detection preview: its memory budget of " + std::to_string(detection.preview_memory) + " bytes is below the " +
            std::to_string(fixed_bytes) + " bytes it holds whatever the budget (" + std::to_string(shape.ring_layers) +
            " slices of " + std::to_string(shape.cells.size[0]) + "x" + std::to_string(shape.cells.size[1]) +
            " cells, a need mask of 1 bit per cell: " + std::to_string(packed_mask_bytes(shape.cells)) + " bytes)");
  const auto start = std::chrono::steady_clock::now();
  // The same samples and pooling as reconstruct_detection_preview.
  const unsigned ratio = shape.ratio, reach = shape.reach;
  DetectionMask result;
  result.grid = shape.cells;
  const std::size_t sx = shape.samples.size[0], sy = shape.samples.size[1], sz = shape.samples.size[2];
  const std::size_t cx = result.grid.size[0], cy = result.grid.size[1], cz = result.grid.size[2];
  const std::size_t area = cx * cy;
  // Slices pooled along x and y, in a ring: cell layer c takes the slices
  // [ratio·c − reach, ratio·c + ratio + reach), at most ratio + 2·reach.
  const std::size_t ring_layers = shape.ring_layers;
  std::vector<float> ring(ring_layers * area);
  std::vector<float> along_x(cx * sy);
  std::vector<float> cells(area);
  std::vector<std::uint16_t> cell_layer(area);
  std::vector<float> otsu_row(shape.otsu_row_floats);
  // What the budget leaves beyond those is shared by the finished cell
  // layers and the samples for Otsu's threshold (one in eight, every even
  // slice's), first come first held; the rest goes to temporary files.
  detail::HostAllowance allowance{detection.preview_memory - fixed_bytes, 0};
  detail::RecordSpool layers(area * sizeof(std::uint16_t), sizeof(std::uint16_t), allowance, detection.temp_directory,
                             "the detection preview's cells");
  detail::RecordSpool otsu_samples(otsu_row.size() * sizeof(float), sizeof(float), allowance, detection.temp_directory,
                                   "the detection preview's samples for Otsu's threshold");
  // Otsu's range, as otsu_threshold finds it (NaN ignored).
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  std::size_t next_layer = 0;
  auto finish_layers_through = [&](std::size_t k) {
    for (; next_layer < cz; ++next_layer) {
      const std::size_t c = next_layer;
      const std::size_t lo_slice = ratio * c >= reach ? ratio * c - reach : 0;
      const std::size_t hi_slice = std::min(sz, ratio * c + ratio + reach);
      if (hi_slice - 1 > k) return;
      std::fill(cells.begin(), cells.end(), -std::numeric_limits<float>::infinity());
      for (std::size_t z = lo_slice; z < hi_slice; ++z) {
        const float* pooled = &ring[(z % ring_layers) * area];
        for (std::size_t i = 0; i < area; ++i) cells[i] = std::max(cells[i], pooled[i]);
      }
      for (std::size_t i = 0; i < area; ++i) cell_layer[i] = cell_bits(cells[i]);
      layers.put(c, cell_layer.data());
    }
  };
  reconstruct_thinned(projections, geometry, options, shape.samples, detection.rule.thinning,
                      [&](std::uint32_t k, const float* values) {
                        for (std::size_t j = 0; j < sy; ++j)
                          pool_line(values + j * sx, sx, 1, ratio, reach, &along_x[j * cx], cx, 1);
                        float* pooled = &ring[(k % ring_layers) * area];
                        for (std::size_t i = 0; i < cx; ++i)
                          pool_line(&along_x[i], sy, cx, ratio, reach, pooled + i, cy, cx);
                        if (k % 2 == 0) {
                          std::size_t n = 0;
                          for (std::size_t j = 0; j < sy; j += 2)
                            for (std::size_t i = 0; i < sx; i += 2) {
                              const float v = values[j * sx + i];
                              otsu_row[n++] = v;
                              if (!std::isnan(v)) lo = std::min(lo, v), hi = std::max(hi, v);
                            }
                          otsu_samples.put(k / 2, otsu_row.data());
                        }
                        finish_layers_through(k);
                      });
  const bool distributed = options.exchange && options.exchange->size() > 1;
  const bool producer = !distributed || options.exchange->rank() == 0;
  if (producer && next_layer != cz) throw std::logic_error("detection preview: not every cell layer was pooled");
  result.peak_preview_bytes = fixed_bytes + allowance.held;
  result.spilled_bytes = layers.spilled_bytes() + otsu_samples.spilled_bytes();
  result.spilled_raw_bytes = layers.spilled_raw_bytes() + otsu_samples.spilled_raw_bytes();
  // Otsu's threshold of the samples, as otsu_threshold over all of them at
  // once: the same range and the same 256 bins, the histogram added to
  // record by record (the samples are not all held: issue 23).
  std::vector<float> otsu{lo};
  if (producer && hi > lo) {
    std::vector<double> histogram(256, 0.0);
    for (std::size_t r = 0; r < otsu_samples.count(); ++r) {
      otsu_samples.get(r, otsu_row.data());
      add_to_otsu_histogram(otsu_row.data(), otsu_row.size(), lo, hi, histogram);
    }
    otsu[0] = otsu_threshold_from_histogram(histogram, lo, hi);
  }
  otsu_samples.release();
  std::vector<float>().swap(otsu_row);
  share(options, otsu);
  result.otsu_threshold = otsu[0];
  result.threshold = detection.threshold ? *detection.threshold
                                         : static_cast<float>(detection.rule.otsu_share * result.otsu_threshold);
  // The second pass: each layer of cells against the threshold, as
  // threshold_keep_mask with no margin (the margin was applied in pooling),
  // into a mask of one bit per cell.
  result.mask.dims = Dims{full.size[0], full.size[1], full.size[2]};
  result.mask.factor = detection.rule.factor;
  result.mask.cells = Dims{result.grid.size[0], result.grid.size[1], result.grid.size[2]};
  result.mask.bits.assign(packed_mask_bytes(result.grid) / 8, 0);
  std::vector<float> decoded(std::size_t{1} << 16);
  for (std::size_t h = 0; h < decoded.size(); ++h) decoded[h] = binary16_to_float(static_cast<std::uint16_t>(h));
  for (std::size_t c = 0; c < cz; ++c) {
    if (producer) {
      layers.get(c, cell_layer.data());
      for (std::size_t i = 0; i < area; ++i) cells[i] = decoded[cell_layer[i]];
    }
    share(options, cells);
    const std::uint64_t first = std::uint64_t{c} * area;
    for (std::size_t i = 0; i < area; ++i)
      if (cells[i] > result.threshold) {
        const std::uint64_t n = first + i;
        result.mask.bits[n >> 6] |= std::uint64_t{1} << (n & 63);
      }
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace ivol::recon
