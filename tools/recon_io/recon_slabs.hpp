// Reconstruction as a source of slabs: the slices of a grid are
// reconstructed when they are read, so that import_to_ivol writes an .ivol
// file straight from the FDK, slab by slab, and the dense volume is never
// held in memory.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol_io.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

// A reconstruction's volume as a converter's input: float32 voxels with the
// grid's geometry, in mm (no samples).
DenseVolume float_volume_of(const recon::VolumeGrid& grid);

class ReconstructionSlabs final : public SlabReader {
 public:
  // float32 samples, the grid's voxel size and origin in mm. `keep_margin`:
  // the margin of import_to_ivol's keep rule (0 without one).
  ReconstructionSlabs(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid, unsigned keep_margin);
  // import_to_ivol reads each slab with `keep_margin` slices on either side,
  // so a read's last 2 × keep_margin slices are read again next: they are
  // kept, not reconstructed again, and nothing else is (at 2048³ a copy of
  // every read was 512 MiB that --memory did not count).
  void read(std::uint32_t z0, std::uint32_t count, void* out) override;

  // Sums over every reconstruction so far.
  const recon::FdkTimings& timings() const { return timings_; }
  std::uint64_t slices_reconstructed() const { return slices_reconstructed_; }
  // Wall-clock seconds spent inside read().
  double read_seconds() const { return read_seconds_; }
  double gups() const;
  // Detector rows × views filtered, summed; the filtered rows' peaks.
  std::uint64_t rows_filtered() const { return rows_filtered_; }
  std::uint64_t filtered_rows_host_bytes() const { return filtered_rows_host_bytes_; }
  std::uint64_t filtered_rows_disk_bytes() const { return filtered_rows_disk_bytes_; }
  std::uint64_t device_bytes_per_slab() const { return device_bytes_per_slab_; }

 private:
  recon::FdkReconstructor& reconstructor_;
  recon::VolumeGrid grid_;
  recon::FdkTimings timings_;
  std::uint64_t slices_reconstructed_ = 0;
  std::uint64_t voxel_updates_ = 0;
  std::uint64_t rows_filtered_ = 0;
  std::uint64_t filtered_rows_host_bytes_ = 0;
  std::uint64_t filtered_rows_disk_bytes_ = 0;
  std::uint64_t device_bytes_per_slab_ = 0;
  double read_seconds_ = 0.0;
  std::uint32_t reread_slices_ = 0;
  std::uint32_t cache_first_ = 0;
  std::vector<float> cache_;  // the last read's last reread_slices_ slices
};

}  // namespace ivol::convert
