#include "recon_slabs.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>

namespace ivol::convert {

DenseVolume float_volume_of(const recon::VolumeGrid& grid) {
  DenseVolume shape;
  shape.dims = Dims{grid.size[0], grid.size[1], grid.size[2]};
  shape.type = SampleType::Float32;
  shape.has_geometry = true;
  shape.voxel_size = {grid.voxel_size[0], grid.voxel_size[1], grid.voxel_size[2]};
  shape.origin = {grid.origin[0], grid.origin[1], grid.origin[2]};
  shape.unit = "mm";
  return shape;
}

namespace {

void add(recon::FdkTimings& into, const recon::FdkTimings& t) {
  into.setup += t.setup;
  into.reading += t.reading;
  into.filtering += t.filtering;
  into.backprojection += t.backprojection;
  into.transfer += t.transfer;
  into.delivery += t.delivery;
  into.total += t.total;
}

}  // namespace

ReconstructionSlabs::ReconstructionSlabs(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                         unsigned keep_margin)
    : reconstructor_(reconstructor), grid_(grid), reread_slices_(2 * keep_margin) {
  shape_ = float_volume_of(grid);
}

void ReconstructionSlabs::read(std::uint32_t z0, std::uint32_t count, void* out) {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t slice = std::size_t{grid_.size[0]} * grid_.size[1];
  float* target = static_cast<float*>(out);
  const std::uint32_t cached = static_cast<std::uint32_t>(cache_.size() / slice);
  std::uint32_t first = z0;
  // Slices at the start of this read that the previous one already made.
  if (z0 >= cache_first_ && z0 < cache_first_ + cached) {
    const std::uint32_t reuse = std::min(count, cache_first_ + cached - z0);
    std::memcpy(target, cache_.data() + (z0 - cache_first_) * slice, reuse * slice * sizeof(float));
    first = z0 + reuse;
  }
  if (first < z0 + count) {
    const recon::FdkReport report = reconstructor_.reconstruct(
        grid_,
        [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
          std::memcpy(target + (k0 - z0) * slice, data, (k1 - k0) * slice * sizeof(float));
        },
        first, z0 + count);
    add(timings_, report.timings);
    voxel_updates_ += report.voxel_updates;
    rows_filtered_ += report.rows_filtered;
    filtered_rows_host_bytes_ = std::max(filtered_rows_host_bytes_, report.filtered_rows_host_bytes);
    filtered_rows_disk_bytes_ = std::max(filtered_rows_disk_bytes_, report.filtered_rows_disk_bytes);
    device_bytes_per_slab_ = std::max(device_bytes_per_slab_, report.device_bytes_per_slab);
    slices_reconstructed_ += z0 + count - first;
  }
  const std::uint32_t kept = std::min(count, reread_slices_);
  cache_first_ = z0 + count - kept;
  cache_.assign(target + (count - kept) * slice, target + count * slice);
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double ReconstructionSlabs::gups() const {
  return timings_.backprojection > 0 ? static_cast<double>(voxel_updates_) / timings_.backprojection * 1e-9 : 0.0;
}

}  // namespace ivol::convert
