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

#include "fdk_session.hpp"

namespace ivol::recon {
using detail::seconds_since;
using detail::SlabPlan;
using detail::SlabRange;

std::vector<detail::DeviceTimings> FdkReconstructor::Impl::device_timings() const {
  std::vector<detail::DeviceTimings> timings;
  for (const auto& d : devices) timings.push_back(d->timings());
  return timings;
}

void FdkReconstructor::Impl::add_timings_since(const std::vector<detail::DeviceTimings>& before,
                                               FdkTimings& timings) const {
  for (std::size_t d = 0; d < devices.size(); ++d) {
    const detail::DeviceTimings& t = devices[d]->timings();
    timings.reading += t.reading - before[d].reading;
    timings.filtering += t.filtering - before[d].filtering;
    timings.backprojection += t.backprojection - before[d].backprojection;
    timings.transfer += t.transfer - before[d].transfer;
  }
}

FdkReport FdkReconstructor::Impl::new_report() const {
  FdkReport report;
  report.short_scan = shape.short_scan;
  report.warnings = shape.warnings;
  for (const auto& h : handles) report.devices.push_back(h.info.name);
  for (const auto& d : devices) report.backprojectors.push_back(d->backprojector());
  return report;
}

std::uint64_t FdkReconstructor::Impl::filter_rows_for(detail::FdkDevice& device, const detail::RowBand& band,
                                                      int max_band_rows) {
  if (!filtered_rows) return static_cast<std::uint64_t>(band.rows()) * geometry.view_count();
  return filtered_rows->ensure(device, band, max_band_rows);
}

void FdkReconstructor::Impl::report_filtered_rows(FdkReport& report) const {
  if (!filtered_rows) return;
  report.filtered_rows_host_bytes = filtered_rows->peak_host_bytes();
  report.filtered_rows_disk_bytes = filtered_rows->peak_disk_bytes();
}

std::vector<detail::FdkDevice*> FdkReconstructor::Impl::device_pointers() const {
  std::vector<detail::FdkDevice*> pointers;
  for (const auto& d : devices) pointers.push_back(d.get());
  return pointers;
}

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

bool native_backprojection_supported() { return detail::native_backprojection_available(); }

double FdkReport::gups() const {
  return timings.backprojection > 0 ? static_cast<double>(voxel_updates) / timings.backprojection * 1e-9 : 0.0;
}

FdkReconstructor::FdkReconstructor(ProjectionSource& projections, const ScanGeometry& geometry,
                                   const FdkOptions& options)
    : impl_(std::make_unique<Impl>(projections, geometry, options)) {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  detail::check_inputs(projections, m.geometry);
  m.shape = detail::analyse_scan(m.geometry);
  m.problem = detail::make_problem(projections, m.geometry, options, m.shape);
  m.problem.projections_mutex = &m.projections_mutex;
  m.handles = detail::choose_devices(options.devices);
  if (options.cache_filtered_rows) {
    m.filtered_rows = std::make_unique<detail::FilteredRows>(
        m.geometry.view_count(), m.geometry.detector.rows, m.geometry.detector.columns,
        options.filtered_rows_memory_limit > 0 ? options.filtered_rows_memory_limit
                                               : detail::default_filtered_rows_budget(),
        options.temp_directory);
    m.problem.filtered_rows = m.filtered_rows.get();
  }
  try {
    for (const detail::DeviceHandle& h : m.handles)
      m.devices.push_back(std::make_unique<detail::FdkDevice>(h, m.problem));
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
  FdkReport report = m.new_report();
  const VolumeGrid grid_copy = grid;
  detail::set_grid(m.problem, grid_copy);
  const SlabRange range{k_begin, k_end};
  const SlabPlan plan = detail::plan_slabs(m.problem, m.handles, m.options, range, /*dense_host_slabs=*/true);
  try {
    for (auto& device : m.devices) device->configure(plan.slices, plan.band_rows);
  } catch (const cl::Error& error) {
    throw std::runtime_error("FDK: allocating device memory: " + detail::describe(error));
  }
  const std::size_t slab_count = (k_end - k_begin + plan.slices - 1) / plan.slices;
  report.slab_count = slab_count;
  report.slab_slices = plan.slices;
  report.device_bytes_per_slab = plan.bytes;
  const std::vector<detail::DeviceTimings> before = m.device_timings();
  const double constructor_setup = m.setup_seconds;
  m.setup_seconds = 0;  // counted in the first reconstruction only
  report.timings.setup = constructor_setup + seconds_since(start);

  auto slab_bounds = [&](std::size_t s) {
    const std::uint32_t first = k_begin + static_cast<std::uint32_t>(s) * plan.slices;
    return SlabRange{first, std::min(k_end, first + plan.slices)};
  };
  const bool distributed = m.options.exchange && m.options.exchange->size() > 1;
  // This process's slabs' bands, in slab order: rows no later slab needs are released.
  std::vector<std::size_t> position(slab_count, 0);
  std::vector<detail::RowBand> bands;
  for (std::size_t s = 0; s < slab_count; ++s)
    if (!distributed || m.options.exchange->owner(s, slab_count) == m.options.exchange->rank()) {
      position[s] = bands.size();
      bands.push_back(detail::rows_for_slab(m.geometry, grid_copy, slab_bounds(s).first, slab_bounds(s).end));
    }
  detail::RowRelease release(m.filtered_rows.get(), bands);
  std::atomic<std::uint64_t> rows_filtered{0};
  try {
    detail::for_each_slab(
        m.device_pointers(), slab_count,
        [&](detail::FdkDevice& device, std::size_t s, std::vector<float>& data) {
          const SlabRange bounds = slab_bounds(s);
          rows_filtered += m.filter_rows_for(device, bands[position[s]], plan.band_rows);
          device.reconstruct_slab(bounds.first, bounds.end, data);
          release.done(position[s]);
        },
        [&](std::size_t s, std::vector<float>& data) {
          const auto delivered = std::chrono::steady_clock::now();
          const SlabRange bounds = slab_bounds(s);
          sink(bounds.first, bounds.end, data.data());
          report.timings.delivery += seconds_since(delivered);
        },
        m.options.exchange.get(), plan.slices);
  } catch (...) {
    m.problem.grid = nullptr;
    throw;
  }
  m.problem.grid = nullptr;

  m.add_timings_since(before, report.timings);
  report.rows_filtered = rows_filtered.load();
  m.report_filtered_rows(report);
  // What this process backprojected: all slices, or its own slabs' when distributed.
  std::uint64_t slices = k_end - k_begin;
  if (distributed) {
    slices = 0;
    for (std::size_t s = 0; s < slab_count; ++s)
      if (m.options.exchange->owner(s, slab_count) == m.options.exchange->rank())
        slices += slab_bounds(s).end - slab_bounds(s).first;
  }
  report.voxel_updates = std::uint64_t{grid.size[0]} * grid.size[1] * slices * m.geometry.view_count();
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

void FdkReconstructor::set_cpu_device_memory_limit(std::uint64_t bytes) {
  impl_->options.cpu_device_memory_limit = bytes;
}

namespace {

// How the filtered rows of a scan split between host and temporary file:
// rows are kept in pairs, a pair of every view at a time
// (fdk_filtered_rows.hpp), in host memory while the budget lasts.
struct RowPairs {
  std::uint64_t pair_bytes = 0;
  std::uint64_t pairs = 0;
  std::uint64_t pairs_held = 0;
};

RowPairs row_pairs(const ScanGeometry& geometry, const FdkOptions& options) {
  RowPairs r;
  r.pair_bytes =
      std::uint64_t{geometry.view_count()} * 2 * static_cast<std::uint64_t>(geometry.detector.columns) * sizeof(float);
  r.pairs = (static_cast<std::uint64_t>(geometry.detector.rows) + 1) / 2;
  const std::uint64_t host = options.filtered_rows_memory_limit > 0 ? options.filtered_rows_memory_limit
                                                                    : detail::default_filtered_rows_budget();
  r.pairs_held = r.pair_bytes > 0 ? host / r.pair_bytes : r.pairs;
  return r;
}

}  // namespace

std::uint64_t filtered_rows_disk_bound(const ScanGeometry& geometry, const FdkOptions& options) {
  if (!options.cache_filtered_rows) return 0;
  const RowPairs r = row_pairs(geometry, options);
  return r.pairs > r.pairs_held ? (r.pairs - r.pairs_held) * r.pair_bytes : 0;
}

std::uint64_t filtered_rows_host_bound(const ScanGeometry& geometry, const FdkOptions& options) {
  if (!options.cache_filtered_rows) return 0;
  const RowPairs r = row_pairs(geometry, options);
  return std::min(r.pairs, r.pairs_held) * r.pair_bytes;
}

}  // namespace ivol::recon
