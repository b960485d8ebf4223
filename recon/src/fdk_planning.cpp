#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

#include "fdk_native_backproject.hpp"
#include "fdk_session.hpp"
#include "ivol/error.hpp"

namespace ivol::recon::detail {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void check_inputs(ProjectionSource& projections, const ScanGeometry& geometry) {
  geometry.validate();
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

FdkProblem make_problem(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                        const detail::ScanShape& shape) {
  FdkProblem problem;
  problem.geometry = &geometry;
  problem.projections = &projections;
  problem.fft_in_global_memory = options.fft_in_global_memory;
  problem.native_cpu_backprojection = options.native_cpu_backprojection;
  for (std::size_t v = 0; v < geometry.view_count(); ++v)
    problem.filter_views.push_back(detail::filter_view(geometry, shape, v));
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

void set_grid(FdkProblem& problem, const VolumeGrid& grid) {
  problem.grid = &grid;
  problem.backproject_views.clear();
  for (std::size_t v = 0; v < problem.geometry->view_count(); ++v)
    problem.backproject_views.push_back(detail::backproject_view(*problem.geometry, grid, v));
  BackprojectView miss{};
  miss.depth[3] = 1.0F;
  miss.column[3] = -1e6F;  // clamped into the zero border
  problem.backproject_views.insert(problem.backproject_views.end(), IVOL_BACKPROJECT_BATCH, miss);
}

// The widest band of detector rows among slabs of `slices` slices cutting
// `range`. Estimated from the outer slabs, which see the cone's divergence
// most, and a middle one (plus the rounding of band ends to even rows);
// exact when `every`.
namespace {

int widest_band(const FdkProblem& problem, SlabRange range, std::uint32_t slices, bool every) {
  int widest = 0;
  auto consider = [&](std::uint32_t begin) {
    const std::uint32_t end = std::min(range.end, begin + slices);
    widest = std::max(widest, detail::rows_for_slab(*problem.geometry, *problem.grid, begin, end).rows());
  };
  const std::uint32_t count = range.end - range.first;
  if (every) {
    for (std::uint32_t begin = range.first; begin < range.end; begin += slices) consider(begin);
    return widest;
  }
  for (std::uint32_t offset : {0U, (count / 2) / slices * slices, (count - 1) / slices * slices})
    consider(range.first + offset);
  return std::min(widest + 2, problem.geometry->detector.rows + 1);
}

}  // namespace

SlabPlan plan_slabs(const FdkProblem& problem, const std::vector<detail::DeviceHandle>& devices,
                    const FdkOptions& options, SlabRange range, bool dense_host_slabs) {
  std::uint64_t budget = ~std::uint64_t{0};
  std::uint64_t max_allocation = ~std::uint64_t{0};
  const int n = 1 << problem.log2n;
  bool any_global_fft = problem.fft_in_global_memory;
  for (const detail::DeviceHandle& d : devices) {
    std::uint64_t limit = options.device_memory_limit > 0 ? options.device_memory_limit : d.info.global_memory / 10 * 8;
    if (options.device_memory_limit == 0 && !d.info.is_gpu && options.cpu_device_memory_limit > 0)
      limit = options.cpu_device_memory_limit / devices.size();
    budget = std::min(budget, limit);
    max_allocation = std::min(max_allocation, d.info.max_allocation);
    any_global_fft = any_global_fft || d.info.local_memory < static_cast<std::uint64_t>(2 * n) * 8 + 1024;
  }
  const std::uint64_t slice_bytes =
      std::uint64_t{padded_row(problem.grid->size[0])} * problem.grid->size[1] * sizeof(float);
  // On a CPU device the budget is host memory: with dense slabs it holds the
  // native backprojector's columns (depth padded to its lanes) and, per
  // device, its share of the slab copies in flight (issue 23: at 2048^3 the
  // detection preview's slabs took 2 GB against a 512 MB share).
  bool cpu_device = false, native = false;
  for (const detail::DeviceHandle& d : devices)
    if (!d.info.is_gpu) {
      cpu_device = true;
      native = native || (problem.native_cpu_backprojection && detail::native_backprojection_available());
    }
  const std::uint64_t copies_per_device = (detail::host_slab_copies(devices.size(), cpu_device) + devices.size() - 1) /
                                          std::max<std::size_t>(devices.size(), 1);
  auto host_bytes = [&](std::uint32_t slices) -> std::uint64_t {
    if (!dense_host_slabs || !cpu_device) return 0;
    const std::uint64_t area = std::uint64_t{problem.grid->size[0]} * problem.grid->size[1] * sizeof(float);
    const std::uint64_t lanes = detail::NativeBackprojector::kLanes;
    // The native backprojector holds its columns instead of the OpenCL slab
    // slab_device_bytes counts.
    const std::uint64_t opencl_slab = std::uint64_t{detail::padded_row(problem.grid->size[0])} *
                                      problem.grid->size[1] * detail::padded_slices(slices) * sizeof(float);
    const std::uint64_t columns = area * ((slices + lanes - 1) / lanes * lanes);
    return copies_per_device * area * slices + (native && columns > opencl_slab ? columns - opencl_slab : 0);
  };
  auto fits = [&](std::uint32_t slices, SlabPlan& plan, bool exact = false) {
    plan.slices = slices;
    plan.band_rows = widest_band(problem, range, slices, exact);
    plan.bytes = detail::slab_device_bytes(problem, slices, plan.band_rows, any_global_fft) + host_bytes(slices);
    return plan.bytes <= budget && slice_bytes * detail::padded_slices(slices) <= max_allocation;
  };
  std::uint32_t high = range.end - range.first;
  if (options.max_slab_slices > 0) high = std::min(high, options.max_slab_slices);
  // Distributed: at least one slab per rank, or some ranks would idle.
  if (options.exchange && options.exchange->size() > 1) {
    const auto ranks = static_cast<std::uint32_t>(options.exchange->size());
    high = std::min(high, std::max(1U, (range.end - range.first + ranks - 1) / ranks));
  }
  SlabPlan plan;
  if (fits(high, plan, true)) return plan;
  std::uint32_t low = 1;
  if (!fits(low, plan, true))
    throw Error(ErrorClass::LimitExceeded,
                "FDK: even one slice of " + std::to_string(problem.grid->size[0]) + "x" +
                    std::to_string(problem.grid->size[1]) + " voxels needs " + std::to_string(plan.bytes) +
                    " bytes of device memory, more than the " + std::to_string(budget) +
                    " allowed (--device-memory; a CPU device's share of --memory)");
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

namespace {

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

std::string message_of(const std::exception_ptr& error) {
  try {
    std::rethrow_exception(error);
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "an unknown error";
  }
}

}  // namespace

void for_each_slab(const std::vector<FdkDevice*>& devices, std::size_t count,
                   const std::function<void(FdkDevice&, std::size_t, std::vector<float>&)>& produce,
                   const std::function<void(std::size_t, std::vector<float>&)>& consume, SlabExchange* exchange,
                   std::uint32_t slab_slices) {
  const bool distributed = exchange != nullptr && exchange->size() > 1;
  const int rank = distributed ? exchange->rank() : 0;
  // The slabs this process produces, in increasing order; the queue holds
  // them by their position in this list, so that a rank's memory stays
  // bounded whatever the other ranks own.
  std::vector<std::size_t> mine;
  if (distributed) {
    exchange->agree(slab_slices, "the slab thickness in slices");
    exchange->agree(count, "the number of slabs");
  }
  for (std::size_t s = 0; s < count; ++s)
    if (!distributed || exchange->owner(s, count) == rank) mine.push_back(s);

  bool any_cpu_device = false;
  for (const FdkDevice* device : devices) any_cpu_device = any_cpu_device || !device->on_gpu();
  SlabQueue queue(std::max<std::size_t>(1, slabs_waiting(devices.size(), any_cpu_device)));
  std::atomic<std::size_t> next_position{0};
  std::vector<std::thread> workers;
  for (FdkDevice* device : devices) {
    workers.emplace_back([&, device] {
      try {
        for (std::size_t n = next_position++; n < mine.size(); n = next_position++) {
          std::vector<float> data;
          produce(*device, mine[n], data);
          queue.put(n, std::move(data));
        }
      } catch (const cl::Error& error) {
        queue.fail(std::make_exception_ptr(std::runtime_error("FDK on " + device->name() + ": " + describe(error))));
      } catch (...) {
        queue.fail(std::current_exception());
      }
    });
  }
  std::exception_ptr failure;
  try {
    std::vector<float> data;
    if (!distributed) {
      for (std::size_t s = 0; s < count; ++s) {
        if (!queue.take(s, data)) break;
        consume(s, data);
      }
    } else if (rank == 0) {
      std::size_t position = 0;
      for (std::size_t s = 0; s < count; ++s) {
        const int from = exchange->owner(s, count);
        if (from == 0) {
          if (!queue.take(position++, data)) break;
        } else {
          exchange->receive(s, from, data);
        }
        consume(s, data);
      }
    } else {
      for (std::size_t n = 0; n < mine.size(); ++n) {
        if (!queue.take(n, data)) break;
        exchange->send(mine[n], data);
      }
    }
  } catch (...) {
    failure = std::current_exception();
    queue.fail(failure);
  }
  for (std::thread& t : workers) t.join();
  if (!failure) failure = queue.error();
  if (!failure) return;
  // Rank 0 waits for this rank's slabs: tell it why none will come.
  if (distributed && rank != 0) exchange->report_failure(message_of(failure));
  std::rethrow_exception(failure);
}

}  // namespace ivol::recon::detail
