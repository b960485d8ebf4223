#include "ivol/recon/preview.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>

#include "ivol/keep_mask.hpp"

namespace ivol::recon {

Preview reconstruct_preview(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                            const VolumeGrid& full, unsigned factor) {
  if (factor < 2 || (factor & (factor - 1)) != 0)
    throw std::invalid_argument("preview: the factor must be a power of two, at least 2");
  const auto start = std::chrono::steady_clock::now();
  Preview preview;
  VolumeGrid& coarse = preview.grid;
  for (int a = 0; a < 3; ++a) {
    coarse.size[a] = (full.size[a] + factor - 1) / factor;
    coarse.voxel_size[a] = full.voxel_size[a] * factor;
    coarse.origin[a] = full.origin[a] + 0.5 * (factor - 1) * full.voxel_size[a];
  }
  const unsigned thinning = std::max(1U, factor / 2);
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
  preview.values.resize(coarse.voxel_count());
  const std::size_t slice = std::size_t{coarse.size[0]} * coarse.size[1];
  reconstructor.reconstruct(coarse, [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
    std::copy(data, data + (k1 - k0) * slice, preview.values.begin() + static_cast<std::ptrdiff_t>(k0 * slice));
  });
  // Distributed, only rank 0 received the preview; every rank needs it to
  // generate the same structure.
  if (options.exchange && options.exchange->size() > 1) options.exchange->broadcast(preview.values);
  preview.otsu_threshold = otsu_threshold(preview.values.data(), preview.values.size());
  preview.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return preview;
}

}  // namespace ivol::recon
