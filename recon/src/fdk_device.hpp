// One OpenCL device reconstructing slabs: its context, queue, kernels and
// buffers, sized once for the largest slab of the plan.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "fdk_native_backproject.hpp"
#include "fdk_native_filter.hpp"
#include "fdk_plan.hpp"
#include "opencl_runtime.hpp"

namespace ivol::recon::detail {

// What every device shares: the scan, the grid and the per-view parameters.
class FilteredRows;

struct FdkProblem {
  const ScanGeometry* geometry = nullptr;
  const VolumeGrid* grid = nullptr;
  ProjectionSource* projections = nullptr;
  std::mutex* projections_mutex = nullptr;  // ProjectionSource is single-threaded
  std::vector<FilterView> filter_views;
  // One per view, then IVOL_BACKPROJECT_BATCH views whose rays miss the
  // detector, which pad the last batch.
  std::vector<BackprojectView> backproject_views;
  int log2n = 0;
  std::vector<float> response;
  std::vector<float> twiddles;  // n/2 complex values, interleaved
  bool fft_in_global_memory = false;
  bool native_cpu_backprojection = true;  // FdkOptions::native_cpu_backprojection
  // With FdkOptions::cache_filtered_rows: every band's rows are filtered
  // into it beforehand (fill_filtered_rows), and slabs read them from it.
  const FilteredRows* filtered_rows = nullptr;
};

struct DeviceTimings {
  double reading = 0, filtering = 0, backprojection = 0, transfer = 0;
};

// Slabs are computed in whole stacks of IVOL_BACKPROJECT_DEPTH slices, with
// rows padded to whole work-groups.
std::uint32_t padded_slices(std::uint32_t slices);
std::uint32_t padded_row(std::uint32_t nx);

// Device memory a slab of `slices` slices needing `band_rows` detector rows
// takes, all buffers included.
std::uint64_t slab_device_bytes(const FdkProblem& problem, std::uint32_t slices, int band_rows, bool fft_in_global);

class FdkDevice {
 public:
  // Builds the kernels; `problem` must stay alive and may change its grid
  // between configure() calls.
  FdkDevice(const DeviceHandle& handle, const FdkProblem& problem);
  // Sizes the buffers for slabs of up to `max_slices` slices needing up to
  // `max_band_rows` detector rows, and uploads the grid's view matrices.
  void configure(std::uint32_t max_slices, int max_band_rows);
  // Reconstructs slices [k_begin, k_end) into `out` (x fastest).
  void reconstruct_slab(std::uint32_t k_begin, std::uint32_t k_end, std::vector<float>& out);
  // Backprojects the tasks' voxels, whose rays meet the detector within
  // `band`: `out` gets DEPTH × IVOL_FINE_RUN sums per block ([d][x]), then
  // one per lone voxel, sampled at its centre (lone[0]) or octants (lone[1]).
  void reconstruct_tasks(const RowBand& band, const std::vector<FineTask>& blocks,
                         const std::array<const std::vector<CoarseTask>*, 2>& lone, std::vector<float>& out);
  // Filters rows `band` of views [first_view, first_view + count) into
  // `images`: count images of band.rows() × columns floats (for FilteredRows).
  void filter_to_host(std::size_t first_view, int count, const RowBand& band, std::vector<float>& images);
  const DeviceTimings& timings() const { return timings_; }
  const std::string& name() const { return name_; }
  bool fft_in_global() const { return fft_in_global_; }
  bool on_gpu() const { return on_gpu_; }
  // "native-avx512" when dense slabs are backprojected in native code, else "opencl".
  const char* backprojector() const { return native_ ? "native-avx512" : "opencl"; }

 private:
  // Reads, weights and filters one batch of views into filtered_[parity].
  void filter_batch(int parity, std::size_t first_view, int view_count, const RowBand& band);
  // Copies one batch of views' rows `band` from problem_.filtered_rows
  // into filtered_[parity], in the filter's layout.
  void load_batch(int parity, std::size_t first_view, int view_count, const RowBand& band);
  // Enqueues the backprojection of one filtered batch; `done` gets its last event.
  using Backprojector =
      std::function<void(cl::Buffer& filtered, int stride_rows, std::size_t first_view, cl::Event* done)>;
  // Every batch of views through the filter and `backproject`, two batches
  // in flight so that reading the next overlaps the device's work.
  void run_views(const RowBand& band, const Backprojector& backproject);
  // reconstruct_slab with the native backprojector: the device filters,
  // the host backprojects the filtered bands in place (PoCL's buffers are
  // host memory).
  void reconstruct_slab_native(std::uint32_t k_begin, std::uint32_t k_end, std::vector<float>& out);
  // filter_batch with native_filter_: fdk_weight_rows on the device, then
  // the FFTs in native code into the mapped filtered buffer.
  void filter_batch_native(int parity, std::size_t first_view, int view_count, const RowBand& band);
  void finish_timings();
  double event_seconds(const cl::Event& event) const;
  void collect(std::vector<cl::Event>& events, double& into);

  const FdkProblem& problem_;
  std::string name_;
  bool fft_in_global_ = false;
  bool on_gpu_ = false;
  int filter_local_size_ = 64;
  cl::Context context_;
  cl::CommandQueue queue_;
  cl::Program program_;
  cl::Kernel filter_;
  cl::Kernel weight_;           // fdk_weight_rows: with native_filter_, the filter's first step
  bool native_filter_ = false;  // FFTs in native code (fdk_native_filter.hpp), on CPU devices
  cl::Kernel backproject_;
  cl::Kernel backproject_fine_;
  cl::Kernel backproject_centre_;
  cl::Kernel backproject_octants_;
  cl::Buffer task_sums_;
  cl::Buffer fine_tasks_;
  cl::Buffer centre_tasks_;
  cl::Buffer octant_tasks_;
  cl::Buffer slab_;  // the OpenCL kernel's slab; unused with native_
  std::unique_ptr<NativeBackprojector> native_;
  cl::Buffer filter_views_;
  cl::Buffer backproject_views_;
  cl::Buffer response_;
  cl::Buffer twiddles_;
  cl::Buffer raw_[2];
  cl::Buffer filtered_[2];
  cl::Buffer fft_scratch_;
  std::vector<float> host_raw_[2];
  std::vector<float> host_filtered_[2];  // load_batch's staging
  cl::Event batch_done_[2];
  std::vector<cl::Event> filter_events_, backproject_events_, transfer_events_;
  DeviceTimings timings_;
  int stride_cols_ = 0;
  int max_band_rows_ = 0;
  std::uint32_t max_slices_ = 0;
};

}  // namespace ivol::recon::detail
