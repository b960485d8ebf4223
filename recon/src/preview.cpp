#include "ivol/recon/preview.hpp"

#include <algorithm>
#include <chrono>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>

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

// FDK of `grid` from every `thinning`-th view with thinning² pixels merged
// (fewer where the scan is small); each z-slice goes to `slice` in order, on
// rank 0 only when distributed.
void reconstruct_thinned(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                         const VolumeGrid& grid, unsigned thinning,
                         const std::function<void(std::uint32_t k, const float* values)>& slice) {
  // Keep at least a few pixels and views when the scan is small.
  unsigned bin = thinning;
  while (bin > 1 && (geometry.detector.columns / static_cast<int>(bin) < 16 ||
                     geometry.detector.rows / static_cast<int>(bin) < 16))
    bin /= 2;
  unsigned view_step = thinning;
  while (view_step > 1 && geometry.view_count() / view_step < 32) view_step /= 2;
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
  // Otsu's threshold of the samples, not of the maxima: the samples are a
  // reconstruction of the object, whose histogram the maxima would bias.
  preview.otsu_threshold = otsu_threshold(otsu_samples.data(), otsu_samples.size());
  preview.seconds = seconds_since(start);
  return preview;
}

}  // namespace ivol::recon
