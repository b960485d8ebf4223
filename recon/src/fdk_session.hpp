// What the dense and the structure reconstructions share: the scan's
// per-view setup, the plan that cuts a range of slices into slabs that fit
// the devices, and the delivery of finished slabs in order.
#pragma once

#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "fdk_device.hpp"
#include "fdk_filtered_rows.hpp"
#include "ivol/recon/fdk.hpp"

namespace ivol::recon::detail {

double seconds_since(std::chrono::steady_clock::time_point start);
void check_inputs(ProjectionSource& projections, const ScanGeometry& geometry);
FdkProblem make_problem(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                        const ScanShape& shape);
// Points the problem at `grid` and computes the grid's view matrices.
void set_grid(FdkProblem& problem, const VolumeGrid& grid);

struct SlabRange {
  std::uint32_t first = 0;
  std::uint32_t end = 0;
};

struct SlabPlan {
  std::uint32_t slices = 0;
  int band_rows = 0;
  std::uint64_t bytes = 0;
};

// The thickest slab cutting `range` whose buffers fit every device. With
// dense_host_slabs (dense reconstruction, whose slabs come back to the host
// whole), a CPU device's budget, being host memory, also holds the native
// backprojector's slab and its share of the host copies for_each_slab keeps
// in flight (host_slab_copies).
SlabPlan plan_slabs(const FdkProblem& problem, const std::vector<DeviceHandle>& devices, const FdkOptions& options,
                    SlabRange range, bool dense_host_slabs = false);

// Finished slabs for_each_slab lets wait for the consumer: one more than the
// devices where all are GPUs, so that a GPU never idles while the writer
// catches up; as many as the devices where any is a CPU device, whose cores
// the writer shares (a slab waiting there buys no speed, and its memory,
// taken from the slab budget, makes every slab thinner: bench/RESULTS.md,
// "Thin dense slabs on the CPU").
constexpr std::size_t slabs_waiting(std::size_t devices, bool any_cpu_device) {
  return any_cpu_device ? devices : devices + 1;
}

// Dense slabs for_each_slab holds on the host at once with `devices`
// producing: one being built per device, as many waiting as the queue takes
// (slabs_waiting), one being consumed.
constexpr std::uint64_t host_slab_copies(std::size_t devices, bool any_cpu_device) {
  return std::uint64_t{devices} + slabs_waiting(devices, any_cpu_device) + 1;
}

// Runs produce(device, s, data) for s = 0 .. count − 1 on all devices at
// once, and consume(s, data) on the calling thread in increasing s; at most
// one slab per device waits to be consumed, which bounds host memory.
// With an exchange, the ranks first agree on `slab_slices` and `count`; this
// rank produces only the slabs it owns, rank 0 consumes all of them (the
// others' through the exchange) and the other ranks consume none: they send
// theirs. The exchange is used from the calling thread only.
void for_each_slab(const std::vector<FdkDevice*>& devices, std::size_t count,
                   const std::function<void(FdkDevice&, std::size_t, std::vector<float>&)>& produce,
                   const std::function<void(std::size_t, std::vector<float>&)>& consume,
                   SlabExchange* exchange = nullptr, std::uint32_t slab_slices = 0);

}  // namespace ivol::recon::detail

namespace ivol::recon {

struct FdkReconstructor::Impl {
  ProjectionSource& projections;
  ScanGeometry geometry;
  FdkOptions options;
  detail::ScanShape shape;
  std::mutex projections_mutex;
  detail::FdkProblem problem;
  std::vector<detail::DeviceHandle> handles;
  std::vector<std::unique_ptr<detail::FdkDevice>> devices;
  std::unique_ptr<detail::FilteredRows> filtered_rows;  // with FdkOptions::cache_filtered_rows
  std::vector<detail::FdkDevice*> device_pointers() const;
  // Readies the filtered rows of one slab's band on `device`: with the
  // cache, filters the pairs it lacks; returns rows × views filtered (without
  // the cache, the band's: the device filters it with the slab).
  std::uint64_t filter_rows_for(detail::FdkDevice& device, const detail::RowBand& band, int max_band_rows);
  // The cache's peaks into the report.
  void report_filtered_rows(FdkReport& report) const;
  // A report that already says what the scan and the devices are.
  FdkReport new_report() const;
  // The devices' timings now, and what they added since `before` into a report.
  std::vector<detail::DeviceTimings> device_timings() const;
  void add_timings_since(const std::vector<detail::DeviceTimings>& before, FdkTimings& timings) const;
  double setup_seconds = 0;

  Impl(ProjectionSource& p, const ScanGeometry& g, const FdkOptions& o) : projections(p), geometry(g), options(o) {}
};

}  // namespace ivol::recon
