#include "ivol/recon/fdk.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <map>
#include <memory>
#include <stdexcept>
#include <thread>

#include "fdk_device.hpp"

namespace ivol::recon {
namespace {

using detail::FdkDevice;
using detail::FdkProblem;
using detail::RowBand;

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void check_inputs(ProjectionSource& projections, const ScanGeometry& geometry, const VolumeGrid& grid) {
  geometry.validate();
  grid.validate();
  if (projections.columns() != geometry.detector.columns || projections.rows() != geometry.detector.rows)
    throw std::invalid_argument("FDK: the projections are " + std::to_string(projections.columns()) + "x" +
                                std::to_string(projections.rows()) + " pixels but the geometry's detector is " +
                                std::to_string(geometry.detector.columns) + "x" +
                                std::to_string(geometry.detector.rows));
  if (projections.view_count() != geometry.view_count())
    throw std::invalid_argument("FDK: there are " + std::to_string(projections.view_count()) +
                                " projections but the geometry has " + std::to_string(geometry.view_count()) +
                                " views");
}

FdkProblem make_problem(ProjectionSource& projections, const ScanGeometry& geometry, const VolumeGrid& grid,
                        const FdkOptions& options, const detail::ScanShape& shape) {
  FdkProblem problem;
  problem.geometry = &geometry;
  problem.grid = &grid;
  problem.projections = &projections;
  problem.fft_in_global_memory = options.fft_in_global_memory;
  for (std::size_t v = 0; v < geometry.view_count(); ++v) {
    problem.filter_views.push_back(detail::filter_view(geometry, shape, v));
    problem.backproject_views.push_back(detail::backproject_view(geometry, grid, v));
  }
  BackprojectView miss{};
  miss.depth[3] = 1.0F;
  miss.column[3] = -1e6F;  // clamped into the zero border
  problem.backproject_views.insert(problem.backproject_views.end(), IVOL_BACKPROJECT_BATCH, miss);
  problem.log2n = detail::ramp_log2_length(geometry.detector.columns);
  for (double r : detail::ramp_response(problem.log2n, options.window, options.cutoff))
    problem.response.push_back(static_cast<float>(r));
  const int n = 1 << problem.log2n;
  for (int m = 0; m < n / 2; ++m) {
    problem.twiddles.push_back(static_cast<float>(std::cos(-2.0 * M_PI * m / n)));
    problem.twiddles.push_back(static_cast<float>(std::sin(-2.0 * M_PI * m / n)));
  }
  return problem;
}

// The widest band of detector rows among slabs of `slices` slices. Estimated
// from the outer slabs, which see the cone's divergence most, and a middle
// one (plus the rounding of band ends to even rows); exact when `every`.
int widest_band(const FdkProblem& problem, std::uint32_t slices, bool every) {
  const std::uint32_t nz = problem.grid->size[2];
  int widest = 0;
  auto consider = [&](std::uint32_t begin) {
    const std::uint32_t end = std::min(nz, begin + slices);
    widest = std::max(widest, detail::rows_for_slab(*problem.geometry, *problem.grid, begin, end).rows());
  };
  if (every) {
    for (std::uint32_t begin = 0; begin < nz; begin += slices) consider(begin);
    return widest;
  }
  for (std::uint32_t begin : {0U, (nz / 2) / slices * slices, (nz - 1) / slices * slices}) consider(begin);
  return std::min(widest + 2, problem.geometry->detector.rows + 1);
}

struct SlabPlan {
  std::uint32_t slices = 0;
  int band_rows = 0;
  std::uint64_t bytes = 0;
};

SlabPlan plan_slabs(const FdkProblem& problem, const std::vector<detail::DeviceHandle>& devices,
                    const FdkOptions& options) {
  std::uint64_t budget = ~std::uint64_t{0};
  std::uint64_t max_allocation = ~std::uint64_t{0};
  const int n = 1 << problem.log2n;
  bool any_global_fft = problem.fft_in_global_memory;
  for (const detail::DeviceHandle& d : devices) {
    const std::uint64_t limit =
        options.device_memory_limit > 0 ? options.device_memory_limit : d.info.global_memory / 10 * 8;
    budget = std::min(budget, limit);
    max_allocation = std::min(max_allocation, d.info.max_allocation);
    any_global_fft = any_global_fft || d.info.local_memory < static_cast<std::uint64_t>(2 * n) * 8 + 1024;
  }
  const std::uint32_t nz = problem.grid->size[2];
  const std::uint64_t slice_bytes = std::uint64_t{problem.grid->size[0]} * problem.grid->size[1] * sizeof(float);
  auto fits = [&](std::uint32_t slices, SlabPlan& plan, bool exact = false) {
    plan.slices = slices;
    plan.band_rows = widest_band(problem, slices, exact);
    plan.bytes = detail::slab_device_bytes(problem, slices, plan.band_rows, any_global_fft);
    return plan.bytes <= budget && slice_bytes * slices <= max_allocation;
  };
  std::uint32_t high = nz;
  if (options.max_slab_slices > 0) high = std::min(high, options.max_slab_slices);
  SlabPlan plan;
  if (fits(high, plan, true)) return plan;
  std::uint32_t low = 1;
  if (!fits(low, plan, true))
    throw std::runtime_error("FDK: even one slice of " + std::to_string(problem.grid->size[0]) + "x" +
                             std::to_string(problem.grid->size[1]) + " voxels needs " + std::to_string(plan.bytes) +
                             " bytes of device memory, more than the " + std::to_string(budget) + " allowed");
  while (high - low > 1) {  // largest slab that fits
    const std::uint32_t mid = low + (high - low) / 2;
    SlabPlan candidate;
    if (fits(mid, candidate))
      low = mid;
    else
      high = mid;
  }
  // The search used estimated bands; settle on a slab size whose exact
  // widest band fits.
  while (!fits(low, plan, true)) --low;
  return plan;
}

// Finished slabs, handed to the sink in z order; workers wait when too many
// are ahead of the one the sink needs next, which bounds host memory.
class SlabQueue {
 public:
  explicit SlabQueue(std::size_t capacity) : capacity_(capacity) {}
  void put(std::size_t index, std::vector<float> data) {
    std::unique_lock<std::mutex> lock(mutex_);
    space_.wait(lock, [&] { return index < next_ + capacity_ || failed_; });
    ready_.emplace(index, std::move(data));
    arrived_.notify_all();
  }
  bool take(std::size_t index, std::vector<float>& data) {
    std::unique_lock<std::mutex> lock(mutex_);
    arrived_.wait(lock, [&] { return ready_.count(index) > 0 || failed_; });
    if (failed_) return false;
    data = std::move(ready_[index]);
    ready_.erase(index);
    next_ = index + 1;
    space_.notify_all();
    return true;
  }
  void fail(std::exception_ptr error) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!error_) error_ = error;
    failed_ = true;
    arrived_.notify_all();
    space_.notify_all();
  }
  std::exception_ptr error() {
    std::lock_guard<std::mutex> lock(mutex_);
    return error_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable arrived_, space_;
  std::map<std::size_t, std::vector<float>> ready_;
  std::size_t next_ = 0;
  std::size_t capacity_;
  bool failed_ = false;
  std::exception_ptr error_;
};

}  // namespace

const char* ramp_window_name(RampWindow window) {
  switch (window) {
    case RampWindow::RamLak:
      return "ram-lak";
    case RampWindow::SheppLogan:
      return "shepp-logan";
    case RampWindow::Cosine:
      return "cosine";
    case RampWindow::Hamming:
      return "hamming";
    case RampWindow::Hann:
      return "hann";
  }
  return "?";
}

RampWindow parse_ramp_window(const std::string& name) {
  for (RampWindow w :
       {RampWindow::RamLak, RampWindow::SheppLogan, RampWindow::Cosine, RampWindow::Hamming, RampWindow::Hann})
    if (name == ramp_window_name(w)) return w;
  throw std::invalid_argument("unknown ramp window '" + name + "'; known: ram-lak, shepp-logan, cosine, hamming, hann");
}

double FdkReport::gups() const {
  return timings.backprojection > 0 ? static_cast<double>(voxel_updates) / timings.backprojection * 1e-9 : 0.0;
}

FdkReport reconstruct_fdk(ProjectionSource& projections, const ScanGeometry& geometry, const VolumeGrid& grid,
                          const FdkOptions& options, const SlabSink& sink) {
  const auto start = std::chrono::steady_clock::now();
  check_inputs(projections, geometry, grid);
  FdkReport report;
  const detail::ScanShape shape = detail::analyse_scan(geometry);
  report.short_scan = shape.short_scan;
  report.warnings = shape.warnings;
  std::mutex projections_mutex;
  FdkProblem problem = make_problem(projections, geometry, grid, options, shape);
  problem.projections_mutex = &projections_mutex;

  const std::vector<detail::DeviceHandle> handles = detail::choose_devices(options.devices);
  const SlabPlan plan = plan_slabs(problem, handles, options);
  std::vector<std::unique_ptr<FdkDevice>> devices;
  try {
    for (const detail::DeviceHandle& h : handles) {
      devices.push_back(std::make_unique<FdkDevice>(h, problem, plan.slices, plan.band_rows));
      report.devices.push_back(h.info.name);
    }
  } catch (const cl::Error& error) {
    throw std::runtime_error("FDK: setting up the OpenCL device: " + detail::describe(error));
  }
  const std::uint32_t nz = grid.size[2];
  const std::size_t slab_count = (nz + plan.slices - 1) / plan.slices;
  report.slab_count = slab_count;
  report.slab_slices = plan.slices;
  report.device_bytes_per_slab = plan.bytes;
  report.timings.setup = seconds_since(start);

  SlabQueue queue(devices.size() + 1);
  std::atomic<std::size_t> next_slab{0};
  std::vector<std::thread> workers;
  for (auto& device : devices) {
    workers.emplace_back([&, d = device.get()] {
      try {
        for (std::size_t s = next_slab++; s < slab_count; s = next_slab++) {
          const std::uint32_t k_begin = static_cast<std::uint32_t>(s) * plan.slices;
          const std::uint32_t k_end = std::min(nz, k_begin + plan.slices);
          std::vector<float> data;
          d->reconstruct_slab(k_begin, k_end, data);
          queue.put(s, std::move(data));
        }
      } catch (const cl::Error& error) {
        queue.fail(std::make_exception_ptr(std::runtime_error("FDK on " + d->name() + ": " + detail::describe(error))));
      } catch (...) {
        queue.fail(std::current_exception());
      }
    });
  }
  std::exception_ptr failure;
  try {
    std::vector<float> data;
    for (std::size_t s = 0; s < slab_count; ++s) {
      if (!queue.take(s, data)) break;
      const auto delivered = std::chrono::steady_clock::now();
      const std::uint32_t k_begin = static_cast<std::uint32_t>(s) * plan.slices;
      sink(k_begin, std::min(nz, k_begin + plan.slices), data.data());
      report.timings.delivery += seconds_since(delivered);
    }
  } catch (...) {
    failure = std::current_exception();
    queue.fail(failure);
  }
  for (std::thread& t : workers) t.join();
  if (failure) std::rethrow_exception(failure);
  if (std::exception_ptr error = queue.error()) std::rethrow_exception(error);

  for (const auto& device : devices) {
    report.timings.reading += device->timings().reading;
    report.timings.filtering += device->timings().filtering;
    report.timings.backprojection += device->timings().backprojection;
    report.timings.transfer += device->timings().transfer;
  }
  report.voxel_updates = grid.voxel_count() * geometry.view_count();
  report.timings.total = seconds_since(start);
  return report;
}

std::vector<float> reconstruct_fdk_dense(ProjectionSource& projections, const ScanGeometry& geometry,
                                         const VolumeGrid& grid, const FdkOptions& options, FdkReport* report) {
  std::vector<float> volume(grid.voxel_count());
  const std::size_t slice = std::size_t{grid.size[0]} * grid.size[1];
  FdkReport r = reconstruct_fdk(projections, geometry, grid, options,
                                [&](std::uint32_t k_begin, std::uint32_t k_end, const float* data) {
                                  std::copy(data, data + slice * (k_end - k_begin), volume.data() + slice * k_begin);
                                });
  if (report != nullptr) *report = std::move(r);
  return volume;
}

}  // namespace ivol::recon
