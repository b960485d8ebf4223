#include "fdk_device.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

#include "fdk_filtered_rows.hpp"

namespace ivol::recon::detail {
namespace {

constexpr int kBatch = IVOL_BACKPROJECT_BATCH;
constexpr std::uint32_t kDepth = IVOL_BACKPROJECT_DEPTH;
// Work-group width of the dense kernel; slab rows are padded to it.
constexpr std::uint32_t kGroupWidth = 64;
constexpr int kBorder = IVOL_BAND_BORDER_BEFORE + IVOL_BAND_BORDER_AFTER;

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::uint64_t fft_scratch_bytes(const FdkProblem& problem, int band_rows) {
  const std::uint64_t n = std::uint64_t{1} << problem.log2n;
  const std::uint64_t pairs = static_cast<std::uint64_t>((band_rows + 1) / 2);
  return std::uint64_t{kBatch} * pairs * 2 * n * 2 * sizeof(float);
}

}  // namespace

std::uint32_t padded_slices(std::uint32_t slices) { return (slices + kDepth - 1) / kDepth * kDepth; }

std::uint32_t padded_row(std::uint32_t nx) { return (nx + kGroupWidth - 1) / kGroupWidth * kGroupWidth; }

std::uint64_t slab_device_bytes(const FdkProblem& problem, std::uint32_t slices, int band_rows, bool fft_in_global) {
  const VolumeGrid& grid = *problem.grid;
  const std::uint64_t columns = static_cast<std::uint64_t>(problem.geometry->detector.columns);
  const std::uint64_t slab =
      std::uint64_t{padded_row(grid.size[0])} * grid.size[1] * padded_slices(slices) * sizeof(float);
  const std::uint64_t raw = std::uint64_t{kBatch} * static_cast<std::uint64_t>(band_rows) * columns * sizeof(float);
  const std::uint64_t filtered =
      std::uint64_t{kBatch} * static_cast<std::uint64_t>(band_rows + kBorder) * (columns + kBorder) * sizeof(float);
  const std::uint64_t views = problem.filter_views.size() * (sizeof(FilterView) + sizeof(BackprojectView));
  const std::uint64_t ramp = (std::uint64_t{1} << problem.log2n) * 2 * sizeof(float);
  return slab + 2 * (raw + filtered) + views + ramp + (fft_in_global ? fft_scratch_bytes(problem, band_rows) : 0);
}

FdkDevice::FdkDevice(const DeviceHandle& handle, const FdkProblem& problem)
    : problem_(problem), name_(handle.info.name) {
  const int n = 1 << problem.log2n;
  // Two complex buffers of n per work-group must fit in local memory.
  fft_in_global_ = problem.fft_in_global_memory ||
                   handle.info.local_memory < static_cast<std::uint64_t>(2 * n) * 2 * sizeof(float) + 1024;
  context_ = cl::Context(handle.device);
  queue_ = cl::CommandQueue(context_, handle.device, CL_QUEUE_PROFILING_ENABLE);
  program_ = build_recon_program(context_, handle.device, fft_in_global_ ? "-DIVOL_FFT_IN_GLOBAL" : "");
  filter_ = cl::Kernel(program_, "fdk_filter_rows");
  weight_ = cl::Kernel(program_, "fdk_weight_rows");
  backproject_ = cl::Kernel(program_, "fdk_backproject");
  backproject_fine_ = cl::Kernel(program_, "fdk_backproject_fine");
  backproject_centre_ = cl::Kernel(program_, "fdk_backproject_centre");
  backproject_octants_ = cl::Kernel(program_, "fdk_backproject_octants");
  const std::size_t max_group =
      std::min<std::size_t>(handle.device.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>(),
                            filter_.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(handle.device));
  filter_local_size_ = static_cast<int>(std::min<std::size_t>({static_cast<std::size_t>(n / 2), 256, max_group}));
  stride_cols_ = problem.geometry->detector.columns + kBorder;
  filter_views_ =
      cl::Buffer(context_, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, problem.filter_views.size() * sizeof(FilterView),
                 const_cast<FilterView*>(problem.filter_views.data()));
  response_ = cl::Buffer(context_, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, problem.response.size() * sizeof(float),
                         const_cast<float*>(problem.response.data()));
  twiddles_ = cl::Buffer(context_, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, problem.twiddles.size() * sizeof(float),
                         const_cast<float*>(problem.twiddles.data()));
  on_gpu_ = handle.info.is_gpu;
  if (!handle.info.is_gpu && problem.native_cpu_backprojection && native_backprojection_available())
    native_ = std::make_unique<NativeBackprojector>(std::max(1u, std::thread::hardware_concurrency()));
  native_filter_ = !handle.info.is_gpu && problem.native_cpu_backprojection && native_filter_available();
}

void FdkDevice::configure(std::uint32_t max_slices, int max_band_rows) {
  const VolumeGrid& grid = *problem_.grid;
  const int columns = problem_.geometry->detector.columns;
  const std::size_t slice_bytes = std::size_t{padded_row(grid.size[0])} * grid.size[1] * sizeof(float);
  // Keep buffers that are large enough from an earlier grid of the same shape.
  if (native_) {
    max_slices_ = max_slices;  // the native backprojector holds the slab on the host
  } else if (max_slices > max_slices_ || !slab_() ||
             slab_.getInfo<CL_MEM_SIZE>() < slice_bytes * padded_slices(max_slices)) {
    slab_ = cl::Buffer(context_, CL_MEM_READ_WRITE, slice_bytes * padded_slices(max_slices));
    max_slices_ = max_slices;
  }
  if (max_band_rows > max_band_rows_) {
    const std::size_t raw_floats = static_cast<std::size_t>(kBatch) * max_band_rows * columns;
    const std::size_t filtered_bytes =
        static_cast<std::size_t>(kBatch) * (max_band_rows + kBorder) * stride_cols_ * sizeof(float);
    for (int p = 0; p < 2; ++p) {
      // Read-write: fdk_weight_rows weights the rows in place.
      raw_[p] = cl::Buffer(context_, CL_MEM_READ_WRITE, std::max<std::size_t>(raw_floats, 1) * sizeof(float));
      filtered_[p] = cl::Buffer(context_, CL_MEM_READ_WRITE, filtered_bytes);
      host_raw_[p].resize(raw_floats);
    }
    if (fft_in_global_)
      fft_scratch_ = cl::Buffer(context_, CL_MEM_READ_WRITE, fft_scratch_bytes(problem_, max_band_rows));
    max_band_rows_ = max_band_rows;
  }
  backproject_views_ = cl::Buffer(context_, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                                  problem_.backproject_views.size() * sizeof(BackprojectView),
                                  const_cast<BackprojectView*>(problem_.backproject_views.data()));
}

double FdkDevice::event_seconds(const cl::Event& event) const {
  const cl_ulong start = event.getProfilingInfo<CL_PROFILING_COMMAND_START>();
  const cl_ulong end = event.getProfilingInfo<CL_PROFILING_COMMAND_END>();
  return end > start ? static_cast<double>(end - start) * 1e-9 : 0.0;
}

void FdkDevice::collect(std::vector<cl::Event>& events, double& into) {
  for (const cl::Event& e : events) into += event_seconds(e);
  events.clear();
}

void FdkDevice::filter_batch(int parity, std::size_t first_view, int view_count, const RowBand& band) {
  const int columns = problem_.geometry->detector.columns;
  const std::size_t image = static_cast<std::size_t>(band.rows()) * columns;
  std::vector<float>& host = host_raw_[parity];
  {
    const auto start = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> lock(*problem_.projections_mutex);
    for (int v = 0; v < view_count; ++v)
      problem_.projections->read_rows(first_view + static_cast<std::size_t>(v), band.first, band.end,
                                      host.data() + static_cast<std::size_t>(v) * image);
    timings_.reading += seconds_since(start);
  }
  cl::Event write;
  queue_.enqueueWriteBuffer(raw_[parity], CL_FALSE, 0, image * view_count * sizeof(float), host.data(), nullptr,
                            &write);
  transfer_events_.push_back(write);

  if (native_filter_) {
    filter_batch_native(parity, first_view, view_count, band);
    return;
  }
  const int n = 1 << problem_.log2n;
  const int pairs = (band.rows() + 1) / 2;
  int arg = 0;
  filter_.setArg(arg++, raw_[parity]);
  filter_.setArg(arg++, filtered_[parity]);
  filter_.setArg(arg++, filter_views_);
  filter_.setArg(arg++, static_cast<cl_int>(first_view));
  filter_.setArg(arg++, response_);
  filter_.setArg(arg++, twiddles_);
  filter_.setArg(arg++, static_cast<cl_int>(columns));
  filter_.setArg(arg++, static_cast<cl_int>(band.rows()));
  filter_.setArg(arg++, static_cast<cl_int>(band.first));
  filter_.setArg(arg++, static_cast<cl_int>(problem_.log2n));
  filter_.setArg(arg++, static_cast<cl_int>(stride_cols_));
  filter_.setArg(arg++, static_cast<cl_int>(band.rows() + kBorder));
  if (fft_in_global_)
    filter_.setArg(arg++, fft_scratch_);
  else
    filter_.setArg(arg++, cl::Local(static_cast<std::size_t>(2 * n) * 2 * sizeof(float)));
  cl::Event filtered;
  queue_.enqueueNDRangeKernel(filter_, cl::NullRange,
                              cl::NDRange(static_cast<std::size_t>(filter_local_size_) * pairs, view_count),
                              cl::NDRange(static_cast<std::size_t>(filter_local_size_), 1), nullptr, &filtered);
  filter_events_.push_back(filtered);
}

void FdkDevice::filter_to_host(std::size_t first_view, int count, const RowBand& band, std::vector<float>& images) {
  if (band.rows() > max_band_rows_)
    throw std::logic_error("FDK: filtering " + std::to_string(band.rows()) + " detector rows, planned for " +
                           std::to_string(max_band_rows_));
  const int columns = problem_.geometry->detector.columns;
  const int stride_rows = band.rows() + kBorder;
  filter_batch(0, first_view, count, band);
  images.resize(static_cast<std::size_t>(count) * band.rows() * columns);
  // The rows without the border around them.
  const cl::array<cl::size_type, 3> from{IVOL_BAND_BORDER_BEFORE * sizeof(float), IVOL_BAND_BORDER_BEFORE, 0};
  const cl::array<cl::size_type, 3> to{0, 0, 0};
  const cl::array<cl::size_type, 3> region{columns * sizeof(float), static_cast<cl::size_type>(band.rows()),
                                           static_cast<cl::size_type>(count)};
  cl::Event read;
  queue_.enqueueReadBufferRect(
      filtered_[0], CL_TRUE, from, to, region, stride_cols_ * sizeof(float),
      std::size_t{static_cast<std::size_t>(stride_rows)} * stride_cols_ * sizeof(float), columns * sizeof(float),
      std::size_t{static_cast<std::size_t>(band.rows())} * columns * sizeof(float), images.data(), nullptr, &read);
  transfer_events_.push_back(read);
  finish_timings();
}

void FdkDevice::filter_batch_native(int parity, std::size_t first_view, int view_count, const RowBand& band) {
  const int columns = problem_.geometry->detector.columns;
  int arg = 0;
  weight_.setArg(arg++, raw_[parity]);
  weight_.setArg(arg++, filter_views_);
  weight_.setArg(arg++, static_cast<cl_int>(first_view));
  weight_.setArg(arg++, static_cast<cl_int>(columns));
  weight_.setArg(arg++, static_cast<cl_int>(band.rows()));
  weight_.setArg(arg++, static_cast<cl_int>(band.first));
  cl::Event weighted;
  queue_.enqueueNDRangeKernel(weight_, cl::NullRange, cl::NDRange(columns, band.rows(), view_count), cl::NullRange,
                              nullptr, &weighted);
  filter_events_.push_back(weighted);
  const std::size_t raw_bytes = static_cast<std::size_t>(view_count) * band.rows() * columns * sizeof(float);
  const int stride_rows = band.rows() + kBorder;
  const std::size_t filtered_bytes = static_cast<std::size_t>(kBatch) * stride_rows * stride_cols_ * sizeof(float);
  cl::Event mapped_raw, mapped_filtered;
  const auto* raw = static_cast<const float*>(
      queue_.enqueueMapBuffer(raw_[parity], CL_TRUE, CL_MAP_READ, 0, raw_bytes, nullptr, &mapped_raw));
  // CL_MAP_WRITE, not ..._INVALIDATE_REGION: the zero border stays.
  auto* filtered = static_cast<float*>(queue_.enqueueMapBuffer(filtered_[parity], CL_TRUE, CL_MAP_READ | CL_MAP_WRITE,
                                                               0, filtered_bytes, nullptr, &mapped_filtered));
  transfer_events_.push_back(mapped_raw);
  transfer_events_.push_back(mapped_filtered);
  const auto start = std::chrono::steady_clock::now();
  NativeFilterBatch batch;
  batch.weighted = raw;
  batch.columns = columns;
  batch.band_rows = band.rows();
  batch.view_count = view_count;
  batch.log2n = problem_.log2n;
  batch.twiddles = problem_.twiddles.data();
  batch.response = problem_.response.data();
  batch.filtered = filtered;
  batch.stride_cols = stride_cols_;
  batch.stride_rows = stride_rows;
  filter_rows_native(batch, std::max(1u, std::thread::hardware_concurrency()));
  timings_.filtering += seconds_since(start);
  cl::Event unmapped_raw, unmapped_filtered;
  queue_.enqueueUnmapMemObject(raw_[parity], const_cast<float*>(raw), nullptr, &unmapped_raw);
  queue_.enqueueUnmapMemObject(filtered_[parity], filtered, nullptr, &unmapped_filtered);
  transfer_events_.push_back(unmapped_raw);
  transfer_events_.push_back(unmapped_filtered);
}

void FdkDevice::load_batch(int parity, std::size_t first_view, int view_count, const RowBand& band) {
  const int stride_rows = band.rows() + kBorder;
  const std::size_t floats = static_cast<std::size_t>(kBatch) * stride_rows * stride_cols_;
  std::vector<float>& host = host_filtered_[parity];
  const auto start = std::chrono::steady_clock::now();
  // A parity's first batch of a slab: the border, and the rows of views a
  // short last batch leaves, must hold zeros in this band's layout.
  if (first_view < 2 * static_cast<std::size_t>(kBatch)) host.assign(floats, 0.0F);
  problem_.filtered_rows->load(first_view, view_count, band, host.data(), stride_cols_, stride_rows);
  timings_.reading += seconds_since(start);
  cl::Event write;
  queue_.enqueueWriteBuffer(filtered_[parity], CL_FALSE, 0, floats * sizeof(float), host.data(), nullptr, &write);
  transfer_events_.push_back(write);
}

void FdkDevice::run_views(const RowBand& band, const Backprojector& backproject) {
  const float zero = 0.0F;
  const std::size_t filtered_bytes =
      static_cast<std::size_t>(kBatch) * (band.rows() + kBorder) * stride_cols_ * sizeof(float);
  for (int p = 0; p < 2; ++p) {
    cl::Event fill;
    queue_.enqueueFillBuffer(filtered_[p], zero, 0, filtered_bytes, nullptr, &fill);
    transfer_events_.push_back(fill);
  }
  if (band.rows() == 0) return;  // the voxels project off the detector
  const std::size_t views = problem_.geometry->view_count();
  int parity = 0;
  for (std::size_t first = 0; first < views; first += kBatch, parity ^= 1) {
    // The host buffer of this parity is free once its last batch is done.
    if (batch_done_[parity]()) batch_done_[parity].wait();
    const int count = static_cast<int>(std::min<std::size_t>(kBatch, views - first));
    if (problem_.filtered_rows != nullptr)
      load_batch(parity, first, count, band);
    else
      filter_batch(parity, first, count, band);
    batch_done_[parity] = cl::Event();
    backproject(filtered_[parity], band.rows() + kBorder, first, &batch_done_[parity]);
    // The native backprojector leaves no event: it has finished with the batch.
    if (batch_done_[parity]()) backproject_events_.push_back(batch_done_[parity]);
    queue_.flush();
  }
}

void FdkDevice::finish_timings() {
  for (cl::Event& e : batch_done_) e = cl::Event();
  collect(filter_events_, timings_.filtering);
  collect(backproject_events_, timings_.backprojection);
  collect(transfer_events_, timings_.transfer);
}

void FdkDevice::reconstruct_slab(std::uint32_t k_begin, std::uint32_t k_end, std::vector<float>& out) {
  if (native_) {
    reconstruct_slab_native(k_begin, k_end, out);
    return;
  }
  const VolumeGrid& grid = *problem_.grid;
  const std::uint32_t slices = k_end - k_begin;
  const std::uint32_t row = padded_row(grid.size[0]);
  const std::size_t slice_bytes = std::size_t{row} * grid.size[1] * sizeof(float);
  const RowBand band = rows_for_slab(*problem_.geometry, grid, k_begin, k_end);
  if (band.rows() > max_band_rows_)
    throw std::logic_error("FDK: slab needs " + std::to_string(band.rows()) + " detector rows, planned for " +
                           std::to_string(max_band_rows_));
  cl::Event fill;
  queue_.enqueueFillBuffer(slab_, 0.0F, 0, slice_bytes * padded_slices(slices), nullptr, &fill);
  transfer_events_.push_back(fill);
  run_views(band, [&](cl::Buffer& filtered, int stride_rows, std::size_t first_view, cl::Event* done) {
    int arg = 0;
    backproject_.setArg(arg++, slab_);
    backproject_.setArg(arg++, static_cast<cl_int>(row));
    backproject_.setArg(arg++, static_cast<cl_int>(grid.size[1]));
    backproject_.setArg(arg++, static_cast<cl_int>(k_begin));
    backproject_.setArg(arg++, filtered);
    backproject_.setArg(arg++, static_cast<cl_int>(stride_cols_));
    backproject_.setArg(arg++, static_cast<cl_int>(stride_rows));
    backproject_.setArg(arg++, static_cast<cl_int>(band.first));
    backproject_.setArg(arg++, backproject_views_);
    backproject_.setArg(arg++, static_cast<cl_int>(first_view));
    queue_.enqueueNDRangeKernel(backproject_, cl::NullRange,
                                cl::NDRange(row, grid.size[1], padded_slices(slices) / kDepth),
                                cl::NDRange(kGroupWidth, 1, 1), nullptr, done);
  });
  // The voxels without the rows' padding.
  out.resize(std::size_t{grid.size[0]} * grid.size[1] * slices);
  cl::Event read;
  const cl::array<cl::size_type, 3> origin{0, 0, 0};
  const cl::array<cl::size_type, 3> region{grid.size[0] * sizeof(float), grid.size[1], slices};
  queue_.enqueueReadBufferRect(slab_, CL_TRUE, origin, origin, region, std::size_t{row} * sizeof(float), slice_bytes,
                               grid.size[0] * sizeof(float), std::size_t{grid.size[0]} * grid.size[1] * sizeof(float),
                               out.data(), nullptr, &read);
  transfer_events_.push_back(read);
  finish_timings();
}

void FdkDevice::reconstruct_slab_native(std::uint32_t k_begin, std::uint32_t k_end, std::vector<float>& out) {
  const VolumeGrid& grid = *problem_.grid;
  const RowBand band = rows_for_slab(*problem_.geometry, grid, k_begin, k_end);
  if (band.rows() > max_band_rows_)
    throw std::logic_error("FDK: slab needs " + std::to_string(band.rows()) + " detector rows, planned for " +
                           std::to_string(max_band_rows_));
  native_->start_slab(grid.size[0], grid.size[1], k_begin, k_end - k_begin);
  run_views(band, [&](cl::Buffer& filtered, int stride_rows, std::size_t first_view, cl::Event*) {
    const std::size_t bytes = static_cast<std::size_t>(kBatch) * stride_rows * stride_cols_ * sizeof(float);
    cl::Event mapped;
    const auto* data =
        static_cast<const float*>(queue_.enqueueMapBuffer(filtered, CL_TRUE, CL_MAP_READ, 0, bytes, nullptr, &mapped));
    transfer_events_.push_back(mapped);
    const auto start = std::chrono::steady_clock::now();
    native_->add_batch(data, stride_cols_, stride_rows, band.first, problem_.backproject_views.data() + first_view);
    timings_.backprojection += seconds_since(start);
    cl::Event unmapped;
    queue_.enqueueUnmapMemObject(filtered, const_cast<float*>(data), nullptr, &unmapped);
    transfer_events_.push_back(unmapped);
  });
  const auto start = std::chrono::steady_clock::now();
  native_->finish_slab(out);
  timings_.transfer += seconds_since(start);
  queue_.finish();
  finish_timings();
}

void FdkDevice::reconstruct_tasks(const RowBand& band, const std::vector<FineTask>& blocks,
                                  const std::array<const std::vector<CoarseTask>*, 2>& lone, std::vector<float>& out) {
  if (band.rows() > max_band_rows_)
    throw std::logic_error("FDK: brick slab needs " + std::to_string(band.rows()) + " detector rows, planned for " +
                           std::to_string(max_band_rows_));
  const std::size_t block_outputs = blocks.size() * kDepth * IVOL_FINE_RUN;
  const std::size_t outputs = block_outputs + lone[0]->size() + lone[1]->size();
  out.assign(outputs, 0.0F);
  if (outputs == 0) return;
  // Task lists and their sums, in one allocation each, kept between slabs.
  auto upload = [&](cl::Buffer& buffer, const void* data, std::size_t bytes) {
    if (!buffer() || buffer.getInfo<CL_MEM_SIZE>() < std::max<std::size_t>(bytes, 1))
      buffer = cl::Buffer(context_, CL_MEM_READ_WRITE, std::max<std::size_t>(bytes, 1));
    if (bytes == 0) return;
    cl::Event copy;
    queue_.enqueueWriteBuffer(buffer, CL_FALSE, 0, bytes, data, nullptr, &copy);
    transfer_events_.push_back(copy);
  };
  // On a CPU device with the native backprojector every task is summed on
  // the host, straight into `out`, with the kernels' bits: nothing to upload.
  const bool native_tasks = native_ != nullptr;
  if (!native_tasks) {
    upload(task_sums_, nullptr, 0);
    if (task_sums_.getInfo<CL_MEM_SIZE>() < outputs * sizeof(float))
      task_sums_ = cl::Buffer(context_, CL_MEM_READ_WRITE, outputs * sizeof(float));
    cl::Event fill;
    queue_.enqueueFillBuffer(task_sums_, 0.0F, 0, outputs * sizeof(float), nullptr, &fill);
    transfer_events_.push_back(fill);
    upload(fine_tasks_, blocks.data(), blocks.size() * sizeof(FineTask));
    upload(centre_tasks_, lone[0]->data(), lone[0]->size() * sizeof(CoarseTask));
    upload(octant_tasks_, lone[1]->data(), lone[1]->size() * sizeof(CoarseTask));
  }

  struct Launch {
    cl::Kernel* kernel;
    cl::Buffer* tasks;
    std::size_t count;
    std::size_t offset;
    bool blocks;
  };
  std::vector<Launch> launches;
  if (!native_tasks) {
    if (!blocks.empty()) launches.push_back({&backproject_fine_, &fine_tasks_, blocks.size(), 0, true});
    if (!lone[0]->empty())
      launches.push_back({&backproject_centre_, &centre_tasks_, lone[0]->size(), block_outputs, false});
    if (!lone[1]->empty())
      launches.push_back(
          {&backproject_octants_, &octant_tasks_, lone[1]->size(), block_outputs + lone[0]->size(), false});
  }
  run_views(band, [&](cl::Buffer& filtered, int stride_rows, std::size_t first_view, cl::Event* done) {
    for (std::size_t l = 0; l < launches.size(); ++l) {
      const Launch& launch = launches[l];
      cl::Kernel& kernel = *launch.kernel;
      int arg = 0;
      kernel.setArg(arg++, task_sums_);
      kernel.setArg(arg++, static_cast<cl_uint>(launch.offset));
      kernel.setArg(arg++, *launch.tasks);
      kernel.setArg(arg++, static_cast<cl_int>(launch.count));
      kernel.setArg(arg++, filtered);
      kernel.setArg(arg++, static_cast<cl_int>(stride_cols_));
      kernel.setArg(arg++, static_cast<cl_int>(stride_rows));
      kernel.setArg(arg++, static_cast<cl_int>(band.first));
      kernel.setArg(arg++, backproject_views_);
      kernel.setArg(arg++, static_cast<cl_int>(first_view));
      cl::Event event;
      cl::Event* target = l + 1 == launches.size() ? done : &event;
      if (launch.blocks) {
        queue_.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(IVOL_FINE_RUN, launch.count),
                                    cl::NDRange(IVOL_FINE_RUN, 1), nullptr, target);
      } else {
        const std::size_t local = 64;
        queue_.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange((launch.count + local - 1) / local * local),
                                    cl::NDRange(local), nullptr, target);
      }
      if (target == &event) backproject_events_.push_back(event);
    }
    if (native_tasks) {
      const std::size_t bytes = static_cast<std::size_t>(kBatch) * stride_rows * stride_cols_ * sizeof(float);
      cl::Event mapped;
      const auto* data = static_cast<const float*>(
          queue_.enqueueMapBuffer(filtered, CL_TRUE, CL_MAP_READ, 0, bytes, nullptr, &mapped));
      transfer_events_.push_back(mapped);
      const auto start = std::chrono::steady_clock::now();
      const BackprojectView* views = problem_.backproject_views.data() + first_view;
      if (!blocks.empty())
        native_->add_fine_batch(data, stride_cols_, stride_rows, band.first, views, blocks.data(), blocks.size(),
                                out.data());
      native_->add_lone_batch(data, stride_cols_, stride_rows, band.first, views, lone[0]->data(), lone[0]->size(), 1,
                              out.data() + block_outputs);
      native_->add_lone_batch(data, stride_cols_, stride_rows, band.first, views, lone[1]->data(), lone[1]->size(), 8,
                              out.data() + block_outputs + lone[0]->size());
      timings_.backprojection += seconds_since(start);
      cl::Event unmapped;
      queue_.enqueueUnmapMemObject(filtered, const_cast<float*>(data), nullptr, &unmapped);
      transfer_events_.push_back(unmapped);
    }
  });
  if (!native_tasks) {
    cl::Event read;
    queue_.enqueueReadBuffer(task_sums_, CL_TRUE, 0, outputs * sizeof(float), out.data(), nullptr, &read);
    transfer_events_.push_back(read);
  }
  queue_.finish();
  finish_timings();
}

}  // namespace ivol::recon::detail
