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

struct SlabRange {
  std::uint32_t first = 0;
  std::uint32_t end = 0;
};

// The widest band of detector rows among slabs of `slices` slices cutting
// `range`. Estimated from the outer slabs, which see the cone's divergence
// most, and a middle one (plus the rounding of band ends to even rows);
// exact when `every`.
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

struct SlabPlan {
  std::uint32_t slices = 0;
  int band_rows = 0;
  std::uint64_t bytes = 0;
};

SlabPlan plan_slabs(const FdkProblem& problem, const std::vector<detail::DeviceHandle>& devices,
                    const FdkOptions& options, SlabRange range) {
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
  const std::uint64_t slice_bytes = std::uint64_t{problem.grid->size[0]} * problem.grid->size[1] * sizeof(float);
  auto fits = [&](std::uint32_t slices, SlabPlan& plan, bool exact = false) {
    plan.slices = slices;
    plan.band_rows = widest_band(problem, range, slices, exact);
    plan.bytes = detail::slab_device_bytes(problem, slices, plan.band_rows, any_global_fft);
    return plan.bytes <= budget && slice_bytes * detail::padded_slices(slices) <= max_allocation;
  };
  std::uint32_t high = range.end - range.first;
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

struct FdkReconstructor::Impl {
  ProjectionSource& projections;
  ScanGeometry geometry;
  FdkOptions options;
  detail::ScanShape shape;
  std::mutex projections_mutex;
  FdkProblem problem;
  std::vector<detail::DeviceHandle> handles;
  std::vector<std::unique_ptr<FdkDevice>> devices;
  double setup_seconds = 0;

  Impl(ProjectionSource& p, const ScanGeometry& g, const FdkOptions& o) : projections(p), geometry(g), options(o) {}
};

FdkReconstructor::FdkReconstructor(ProjectionSource& projections, const ScanGeometry& geometry,
                                   const FdkOptions& options)
    : impl_(std::make_unique<Impl>(projections, geometry, options)) {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  check_inputs(projections, m.geometry);
  m.shape = detail::analyse_scan(m.geometry);
  m.problem = make_problem(projections, m.geometry, options, m.shape);
  m.problem.projections_mutex = &m.projections_mutex;
  m.handles = detail::choose_devices(options.devices);
  try {
    for (const detail::DeviceHandle& h : m.handles) m.devices.push_back(std::make_unique<FdkDevice>(h, m.problem));
  } catch (const cl::Error& error) {
    throw std::runtime_error("FDK: setting up the OpenCL device: " + detail::describe(error));
  }
  m.setup_seconds = seconds_since(start);
}

FdkReconstructor::~FdkReconstructor() = default;

std::vector<std::string> FdkReconstructor::device_names() const {
  std::vector<std::string> names;
  for (const auto& h : impl_->handles) names.push_back(h.info.name);
  return names;
}

const std::vector<std::string>& FdkReconstructor::warnings() const { return impl_->shape.warnings; }

bool FdkReconstructor::short_scan() const { return impl_->shape.short_scan; }

FdkReport FdkReconstructor::reconstruct(const VolumeGrid& grid, const SlabSink& sink, std::uint32_t k_begin,
                                        std::uint32_t k_end) {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  grid.validate();
  k_end = std::min(k_end, grid.size[2]);
  if (k_begin >= k_end)
    throw std::invalid_argument("FDK: slices " + std::to_string(k_begin) + ".." + std::to_string(k_end) +
                                " of a volume of " + std::to_string(grid.size[2]) + " are empty");
  FdkReport report;
  report.short_scan = m.shape.short_scan;
  report.warnings = m.shape.warnings;
  report.devices = device_names();
  const VolumeGrid grid_copy = grid;
  set_grid(m.problem, grid_copy);
  const SlabRange range{k_begin, k_end};
  const SlabPlan plan = plan_slabs(m.problem, m.handles, m.options, range);
  try {
    for (auto& device : m.devices) device->configure(plan.slices, plan.band_rows);
  } catch (const cl::Error& error) {
    throw std::runtime_error("FDK: allocating device memory: " + detail::describe(error));
  }
  const std::size_t slab_count = (k_end - k_begin + plan.slices - 1) / plan.slices;
  report.slab_count = slab_count;
  report.slab_slices = plan.slices;
  report.device_bytes_per_slab = plan.bytes;
  std::vector<detail::DeviceTimings> before;
  for (const auto& device : m.devices) before.push_back(device->timings());
  const double constructor_setup = m.setup_seconds;
  m.setup_seconds = 0;  // counted in the first reconstruction only
  report.timings.setup = constructor_setup + seconds_since(start);

  SlabQueue queue(m.devices.size() + 1);
  std::atomic<std::size_t> next_slab{0};
  auto slab_bounds = [&](std::size_t s) {
    const std::uint32_t first = k_begin + static_cast<std::uint32_t>(s) * plan.slices;
    return SlabRange{first, std::min(k_end, first + plan.slices)};
  };
  std::vector<std::thread> workers;
  for (auto& device : m.devices) {
    workers.emplace_back([&, d = device.get()] {
      try {
        for (std::size_t s = next_slab++; s < slab_count; s = next_slab++) {
          const SlabRange bounds = slab_bounds(s);
          std::vector<float> data;
          d->reconstruct_slab(bounds.first, bounds.end, data);
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
      const SlabRange bounds = slab_bounds(s);
      sink(bounds.first, bounds.end, data.data());
      report.timings.delivery += seconds_since(delivered);
    }
  } catch (...) {
    failure = std::current_exception();
    queue.fail(failure);
  }
  for (std::thread& t : workers) t.join();
  m.problem.grid = nullptr;
  if (failure) std::rethrow_exception(failure);
  if (std::exception_ptr error = queue.error()) std::rethrow_exception(error);

  for (std::size_t d = 0; d < m.devices.size(); ++d) {
    const detail::DeviceTimings& t = m.devices[d]->timings();
    report.timings.reading += t.reading - before[d].reading;
    report.timings.filtering += t.filtering - before[d].filtering;
    report.timings.backprojection += t.backprojection - before[d].backprojection;
    report.timings.transfer += t.transfer - before[d].transfer;
  }
  report.voxel_updates = std::uint64_t{grid.size[0]} * grid.size[1] * (k_end - k_begin) * m.geometry.view_count();
  report.timings.total = constructor_setup + seconds_since(start);
  return report;
}

FdkReport reconstruct_fdk(ProjectionSource& projections, const ScanGeometry& geometry, const VolumeGrid& grid,
                          const FdkOptions& options, const SlabSink& sink) {
  const auto start = std::chrono::steady_clock::now();
  FdkReconstructor reconstructor(projections, geometry, options);
  FdkReport report = reconstructor.reconstruct(grid, sink);
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
