// Dense FDK backprojection in native code for CPU devices, beside the OpenCL
// kernel (kernels/fdk_backproject.cl), which stays the GPU path.
//
// Under PoCL the kernel is vectorised along x and needs four 8-wide gathers
// per voxel update. Here a thread walks a voxel column (i, j) along k: for a
// circular scan the column keeps one detector column and weight per view, so
// the detector rows it meets lie on two neighbouring columns of the filtered
// band. With the band transposed (columns contiguous), sixteen voxels along
// k need two contiguous 32-row strips, interpolated between the columns in
// two vector operations, and a register permute picks each voxel's two rows:
// no gathers unless the sixteen voxels span more than 31 detector rows.
//
// The arithmetic is the kernel's operation for operation, with the fused
// multiply-adds where the OpenCL compiler contracts (clang's default for
// OpenCL C), so a voxel gets the same bits from either path; the structure
// path (fdk_backproject_fine, still OpenCL) relies on that, and
// test_fdk_native checks it.
#pragma once

#include <cstdint>
#include <vector>

#include "recon_layout.h"

namespace ivol::recon::detail {

// True when this CPU runs the native backprojector (AVX-512F, checked at
// run time; the library itself is built for the baseline x86-64).
bool native_backprojection_available();

// Accumulates one slab in voxel columns (k fastest) over batches of views.
class NativeBackprojector {
 public:
  explicit NativeBackprojector(unsigned threads);
  // Starts slices [k_first, k_first + slices) of an nx × ny grid at zero.
  void start_slab(std::uint32_t nx, std::uint32_t ny, std::uint32_t k_first, std::uint32_t slices);
  // Adds IVOL_BACKPROJECT_BATCH views: `filtered` holds their bands as the
  // filter kernel writes them (view, row, column; stride_rows × stride_cols
  // each, zero borders included), views[v] is view v's matrix.
  void add_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                 const BackprojectView* views);
  // The slab as nx·ny·slices floats, x fastest.
  void finish_slab(std::vector<float>& out) const;

  // Adds the same batch to a structure's blocks of voxels, as the kernel
  // fdk_backproject_fine does, with its bits: the voxel (x, d) of task t into
  // sums[(t·IVOL_BACKPROJECT_DEPTH + d)·IVOL_FINE_RUN + x]. Each task's eight
  // voxels along k take one vector, as a dense column's sixteen do.
  void add_fine_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                      const BackprojectView* views, const FineTask* tasks, std::size_t task_count, float* sums);
  // Adds the same batch to lone coarse voxels, as fdk_backproject_centre
  // (octants 1) or fdk_backproject_octants (8) do, with their bits: task t
  // into sums[t]. Reads `filtered` as it is (no transpose).
  void add_lone_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                      const BackprojectView* views, const CoarseTask* tasks, std::size_t task_count, int octants,
                      float* sums) const;

  // One lane of the vector loop (16 voxels along k) for one view.
  static constexpr std::uint32_t kLanes = 16;

 private:
  unsigned threads_;
  std::uint32_t nx_ = 0, ny_ = 0, k_first_ = 0, slices_ = 0, depth_ = 0;  // depth_: slices in whole lanes
  std::vector<float> columns_;                                            // [j][i][k], depth_ per column
  // A thin slab (a few slices, as a tight --memory gives at 2048^3) is
  // summed as fine tasks of 16 columns by 8 slices instead of columns: a
  // column's per-view scalars then serve 8 points, not a vector of 16 lanes
  // most of which lie past the slab, and they are computed 16 at a time.
  bool thin_ = false;
  std::uint32_t tiles_i_ = 0, stacks_ = 0;  // tasks along i (16 columns) and k (8 slices)
  std::vector<float> task_sums_;            // [stack][j][tile][d][x]
  std::vector<float> transposed_;           // per view [column][row], then a strip's overrun of zeros

  // The batch's bands into transposed_ (columns contiguous).
  void transpose(const float* filtered, int stride_cols, int stride_rows);
};

}  // namespace ivol::recon::detail
