// FDK straight into an inhomogeneous structure (Betz et al., section 5):
// only the structure's voxels are backprojected, each at its own size.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fdk_session.hpp"

namespace ivol::recon {
namespace {

static_assert(sizeof(FineTask) == 16, "FineTask must match kernels/recon_layout.h");
static_assert(sizeof(CoarseTask) == 32, "CoarseTask must match kernels/recon_layout.h");

constexpr std::uint32_t kDepth = IVOL_BACKPROJECT_DEPTH;

// The tasks of one slab and where their sums go in the structure's values.
struct SlabTasks {
  std::vector<FineTask> fine;
  std::vector<std::uint64_t> fine_first;   // value index of the stack's first voxel
  std::vector<std::uint32_t> fine_stride;  // value index step along k
  std::vector<CoarseTask> coarse;
  std::vector<std::uint64_t> coarse_value;  // value index
  double k_low = 1e300;                     // extent of the samples along k
  double k_high = -1e300;
};

std::vector<SlabTasks> tasks_by_slab(const VoxelStructure& structure, std::uint32_t slices, std::size_t slab_count) {
  std::vector<SlabTasks> slabs(slab_count);
  for (const Brick& b : structure.bricks()) {
    const bool fine = b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1;
    const std::uint64_t row = b.count[0];
    const std::uint64_t plane = row * b.count[1];
    if (fine) {
      for (std::uint32_t c = 0; c < b.count[2]; c += kDepth)
        for (std::uint32_t y = 0; y < b.count[1]; ++y)
          for (std::uint32_t x = 0; x < b.count[0]; ++x) {
            const std::uint32_t k = b.origin[2] + c;
            SlabTasks& s = slabs[k / slices];
            const std::uint32_t count = std::min(kDepth, b.count[2] - c);
            s.fine.push_back(FineTask{static_cast<float>(b.origin[0] + x), static_cast<float>(b.origin[1] + y),
                                      static_cast<float>(k), count});
            s.fine_first.push_back(b.first_value + c * plane + y * row + x);
            s.fine_stride.push_back(static_cast<std::uint32_t>(plane));
            s.k_low = std::min(s.k_low, static_cast<double>(k));
            s.k_high = std::max(s.k_high, static_cast<double>(k + kDepth - 1));
          }
      continue;
    }
    for (std::uint32_t c = 0; c < b.count[2]; ++c)
      for (std::uint32_t y = 0; y < b.count[1]; ++y)
        for (std::uint32_t x = 0; x < b.count[0]; ++x) {
          // Centre of the coarse voxel as a grid index: full-resolution voxel
          // n covers [n, n + 1), its centre is index n.
          const double ci = b.origin[0] + (x + 0.5) * b.voxel[0] - 0.5;
          const double cj = b.origin[1] + (y + 0.5) * b.voxel[1] - 0.5;
          const double ck = b.origin[2] + (c + 0.5) * b.voxel[2] - 0.5;
          SlabTasks& s =
              slabs[std::min<std::size_t>(static_cast<std::size_t>(ck < 0 ? 0 : ck) / slices, slab_count - 1)];
          CoarseTask t{};
          t.i = static_cast<float>(ci);
          t.j = static_cast<float>(cj);
          t.k = static_cast<float>(ck);
          t.quarter_i = 0.25F * static_cast<float>(b.voxel[0]);
          t.quarter_j = 0.25F * static_cast<float>(b.voxel[1]);
          t.quarter_k = 0.25F * static_cast<float>(b.voxel[2]);
          s.coarse.push_back(t);
          s.coarse_value.push_back(b.first_value + c * plane + y * row + x);
          s.k_low = std::min(s.k_low, ck - t.quarter_k);
          s.k_high = std::max(s.k_high, ck + t.quarter_k);
        }
  }
  return slabs;
}

detail::RowBand band_for(const ScanGeometry& geometry, const VolumeGrid& grid, const SlabTasks& s) {
  if (s.fine.empty() && s.coarse.empty()) return {};
  const double nz = grid.size[2];
  const auto k0 = static_cast<std::uint32_t>(std::clamp(std::floor(s.k_low), 0.0, nz - 1));
  const auto k1 = static_cast<std::uint32_t>(std::clamp(std::ceil(s.k_high) + 1.0, 1.0, nz));
  return detail::rows_for_slab(geometry, grid, k0, std::max(k1, k0 + 1));
}

}  // namespace

FdkReport FdkReconstructor::reconstruct_structure(const VolumeGrid& grid, VoxelStructure& structure) {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  grid.validate();
  const Dims& dims = structure.dims();
  if (dims[0] != grid.size[0] || dims[1] != grid.size[1] || dims[2] != grid.size[2])
    throw std::invalid_argument("FDK: the structure is " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) +
                                "x" + std::to_string(dims[2]) + " voxels, the grid " + std::to_string(grid.size[0]) +
                                "x" + std::to_string(grid.size[1]) + "x" + std::to_string(grid.size[2]));
  FdkReport report;
  report.short_scan = m.shape.short_scan;
  report.warnings = m.shape.warnings;
  report.devices = device_names();
  const VolumeGrid grid_copy = grid;
  detail::set_grid(m.problem, grid_copy);
  // Slabs as thick as a dense reconstruction would use: a slab's task sums
  // never outnumber its voxels by more than the padding of the stacks.
  const detail::SlabPlan plan = detail::plan_slabs(m.problem, m.handles, m.options, {0, grid.size[2]});
  const std::size_t slab_count = (grid.size[2] + plan.slices - 1) / plan.slices;
  const std::vector<SlabTasks> slabs = tasks_by_slab(structure, plan.slices, slab_count);
  std::vector<detail::RowBand> bands;
  int widest = 0;
  for (const SlabTasks& s : slabs) {
    bands.push_back(band_for(m.geometry, grid, s));
    widest = std::max(widest, bands.back().rows());
  }
  try {
    for (auto& device : m.devices) device->configure(1, widest);  // no dense slab: the task sums replace it
  } catch (const cl::Error& error) {
    m.problem.grid = nullptr;
    throw std::runtime_error("FDK: allocating device memory: " + detail::describe(error));
  }
  report.slab_count = slab_count;
  report.slab_slices = plan.slices;
  report.device_bytes_per_slab = plan.bytes;
  std::vector<detail::DeviceTimings> before;
  for (const auto& device : m.devices) before.push_back(device->timings());
  const double constructor_setup = m.setup_seconds;
  m.setup_seconds = 0;
  report.timings.setup = constructor_setup + detail::seconds_since(start);

  std::vector<float>& values = structure.values();
  std::uint64_t samples = 0;
  try {
    detail::for_each_slab(
        m.device_pointers(), slab_count,
        [&](detail::FdkDevice& device, std::size_t s, std::vector<float>& sums) {
          device.reconstruct_tasks(bands[s], slabs[s].fine, slabs[s].coarse, sums);
        },
        [&](std::size_t s, std::vector<float>& sums) {
          const SlabTasks& t = slabs[s];
          for (std::size_t f = 0; f < t.fine.size(); ++f)
            for (std::uint32_t d = 0; d < t.fine[f].count; ++d)
              values[t.fine_first[f] + d * static_cast<std::uint64_t>(t.fine_stride[f])] = sums[f * kDepth + d];
          const std::size_t coarse_base = t.fine.size() * kDepth;
          for (std::size_t c = 0; c < t.coarse.size(); ++c) values[t.coarse_value[c]] = sums[coarse_base + c];
          samples += t.fine.size() * kDepth + t.coarse.size() * 8;
        });
  } catch (...) {
    m.problem.grid = nullptr;
    throw;
  }
  m.problem.grid = nullptr;
  for (std::size_t d = 0; d < m.devices.size(); ++d) {
    const detail::DeviceTimings& t = m.devices[d]->timings();
    report.timings.reading += t.reading - before[d].reading;
    report.timings.filtering += t.filtering - before[d].filtering;
    report.timings.backprojection += t.backprojection - before[d].backprojection;
    report.timings.transfer += t.transfer - before[d].transfer;
  }
  report.voxel_updates = samples * m.geometry.view_count();
  report.timings.total = constructor_setup + detail::seconds_since(start);
  return report;
}

}  // namespace ivol::recon
