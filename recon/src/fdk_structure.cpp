// FDK straight into an inhomogeneous structure (Betz et al., section 5):
// only the structure's voxels are backprojected, each at its own size.
#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "fdk_session.hpp"

namespace ivol::recon {
namespace {

static_assert(sizeof(FineTask) == 32, "FineTask must match kernels/recon_layout.h");
static_assert(sizeof(CoarseTask) == 32, "CoarseTask must match kernels/recon_layout.h");

constexpr std::uint32_t kDepth = IVOL_BACKPROJECT_DEPTH;
constexpr std::uint32_t kRun = IVOL_FINE_RUN;

// Where a block task's sample points lie in its brick.
struct BlockRef {
  std::uint32_t brick;
  std::uint32_t mi, mj, mk;  // the block's first sample on the brick's lattice
};

// The tasks of one slab and where their sums go in the structure's values.
struct SlabTasks {
  std::vector<FineTask> blocks;
  std::vector<BlockRef> block_refs;
  std::vector<CoarseTask> centres;  // lone voxels up to two wide: one sample
  std::vector<CoarseTask> octants;  // wider lone voxels: eight
  std::vector<std::uint64_t> centre_value;
  std::vector<std::uint64_t> octant_value;
  double k_low = 1e300;  // extent of the sample points along k
  double k_high = -1e300;
};

// Sample points per voxel along an axis: the voxel's centre when it is one
// voxel wide, else its two halves' centres (with the other axes: octants).
std::uint32_t points_per_voxel(std::uint32_t edge) { return edge > 1 ? 2 : 1; }

std::vector<SlabTasks> tasks_by_slab(const VoxelStructure& structure, std::uint32_t slices, std::size_t slab_count) {
  std::vector<SlabTasks> slabs(slab_count);
  auto slab_of = [&](double k) {
    return std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 0.0)) / slices, slab_count - 1);
  };
  const std::vector<Brick>& bricks = structure.bricks();
  for (std::uint32_t index = 0; index < bricks.size(); ++index) {
    const Brick& b = bricks[index];
    const bool lone = b.count[0] == 1 && b.count[1] == 1 && b.count[2] == 1;
    const bool fine = b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1;
    // Lone voxels, coarse ones and the single full-resolution voxels an
    // octree leaves at the object's edge, take a work-item each: in a block
    // they would fill one of its 128 lanes. (A fine one's centre sample goes
    // through the dense kernel's arithmetic, so it keeps its bits.)
    if (lone) {
      CoarseTask t{};
      t.i = static_cast<float>(b.origin[0] + 0.5 * b.voxel[0] - 0.5);
      t.j = static_cast<float>(b.origin[1] + 0.5 * b.voxel[1] - 0.5);
      t.k = static_cast<float>(b.origin[2] + 0.5 * b.voxel[2] - 0.5);
      t.quarter_i = 0.25F * static_cast<float>(b.voxel[0]);
      t.quarter_j = 0.25F * static_cast<float>(b.voxel[1]);
      t.quarter_k = 0.25F * static_cast<float>(b.voxel[2]);
      SlabTasks& s = slabs[slab_of(t.k)];
      if (std::max({b.voxel[0], b.voxel[1], b.voxel[2]}) <= 2) {
        s.centres.push_back(t);
        s.centre_value.push_back(b.first_value);
      } else {
        s.octants.push_back(t);
        s.octant_value.push_back(b.first_value);
      }
      s.k_low = std::min(s.k_low, static_cast<double>(t.k - t.quarter_k));
      s.k_high = std::max(s.k_high, static_cast<double>(t.k + t.quarter_k));
      continue;
    }
    // A lattice of sample points: voxel centres, or octant centres of voxels
    // wider than one along an axis; blocks of kRun × kDepth points.
    std::array<std::uint32_t, 3> points{};
    std::array<double, 3> step{}, first{};
    for (int a = 0; a < 3; ++a) {
      points[a] = b.count[a] * points_per_voxel(b.voxel[a]);
      step[a] = static_cast<double>(b.voxel[a]) / points_per_voxel(b.voxel[a]);
      first[a] = b.origin[a] + 0.5 * step[a] - 0.5;
    }
    // Lanes per row: the points along i, rounded up to a power of two; the
    // rest of a block's lanes take the next rows along j.
    std::uint32_t run_i = 1;
    while (run_i < std::min(points[0], kRun)) run_i *= 2;
    const std::uint32_t rows = kRun / run_i;
    for (std::uint32_t mk = 0; mk < points[2]; mk += kDepth)
      for (std::uint32_t mj = 0; mj < points[1]; mj += rows)
        for (std::uint32_t mi = 0; mi < points[0]; mi += run_i) {
          const double k = first[2] + mk * step[2];
          SlabTasks& s = slabs[slab_of(k)];
          const std::uint32_t along_i = std::min(run_i, points[0] - mi);
          const std::uint32_t along_j = std::min(rows, points[1] - mj);
          const std::uint32_t along_k = std::min(kDepth, points[2] - mk);
          FineTask t{};
          t.i = static_cast<float>(first[0] + mi * step[0]);
          t.j = static_cast<float>(first[1] + mj * step[1]);
          t.k = static_cast<float>(k);
          t.step_i = static_cast<float>(step[0]);
          t.step_j = static_cast<float>(step[1]);
          t.step_k = static_cast<float>(step[2]);
          t.run_i = run_i;
          t.count = along_i | (along_j << 8) | (along_k << 16);
          s.blocks.push_back(t);
          s.block_refs.push_back(BlockRef{index, mi, mj, mk});
          s.k_low = std::min(s.k_low, k);
          s.k_high = std::max(s.k_high, k + (kDepth - 1) * step[2]);
        }
  }
  return slabs;
}

// Adds a slab's sums into the structure's values: a full-resolution voxel
// takes its one sum as it is, a coarse one the mean of its points.
void deliver(const VoxelStructure& structure, const SlabTasks& t, const std::vector<float>& sums,
             std::vector<float>& values) {
  const std::vector<Brick>& bricks = structure.bricks();
  for (std::size_t n = 0; n < t.blocks.size(); ++n) {
    const BlockRef& ref = t.block_refs[n];
    const Brick& b = bricks[ref.brick];
    const std::uint32_t per_i = points_per_voxel(b.voxel[0]);
    const std::uint32_t per_j = points_per_voxel(b.voxel[1]);
    const std::uint32_t per_k = points_per_voxel(b.voxel[2]);
    const float weight = 1.0F / static_cast<float>(per_i * per_j * per_k);
    const bool fine = per_i * per_j * per_k == 1;
    const FineTask& task = t.blocks[n];
    const std::uint32_t along_i = task.count & 0xFF;
    const std::uint32_t along_j = (task.count >> 8) & 0xFF;
    const std::uint32_t along_k = task.count >> 16;
    const std::uint64_t row = b.count[0];
    const std::uint64_t plane = row * b.count[1];
    for (std::uint32_t d = 0; d < along_k; ++d) {
      const float* from = &sums[(n * kDepth + d) * kRun];
      for (std::uint32_t y = 0; y < along_j; ++y) {
        const std::uint64_t base = b.first_value + (ref.mk + d) / per_k * plane + (ref.mj + y) / per_j * row;
        for (std::uint32_t x = 0; x < along_i; ++x) {
          float& value = values[base + (ref.mi + x) / per_i];
          const float sum = from[y * task.run_i + x];
          value = fine ? sum : value + weight * sum;
        }
      }
    }
  }
  std::size_t next = t.blocks.size() * kDepth * kRun;
  for (std::size_t c = 0; c < t.centres.size(); ++c) values[t.centre_value[c]] = sums[next++];
  for (std::size_t c = 0; c < t.octants.size(); ++c) values[t.octant_value[c]] = sums[next++];
}

detail::RowBand band_for(const ScanGeometry& geometry, const VolumeGrid& grid, const SlabTasks& s) {
  if (s.blocks.empty() && s.centres.empty() && s.octants.empty()) return {};
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
  FdkReport report = m.new_report();
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
  const std::vector<detail::DeviceTimings> before = m.device_timings();
  const double constructor_setup = m.setup_seconds;
  m.setup_seconds = 0;
  report.timings.setup = constructor_setup + detail::seconds_since(start);

  std::vector<float>& values = structure.values();
  std::fill(values.begin(), values.end(), 0.0F);
  std::uint64_t samples = 0;
  try {
    detail::for_each_slab(
        m.device_pointers(), slab_count,
        [&](detail::FdkDevice& device, std::size_t s, std::vector<float>& sums) {
          device.reconstruct_tasks(bands[s], slabs[s].blocks, {&slabs[s].centres, &slabs[s].octants}, sums);
        },
        [&](std::size_t s, std::vector<float>& sums) {
          const SlabTasks& t = slabs[s];
          deliver(structure, t, sums, values);
          for (const FineTask& f : t.blocks) samples += (f.count & 0xFF) * ((f.count >> 8) & 0xFF) * (f.count >> 16);
          samples += t.centres.size() + 8 * t.octants.size();
        });
  } catch (...) {
    m.problem.grid = nullptr;
    throw;
  }
  m.problem.grid = nullptr;
  m.add_timings_since(before, report.timings);
  report.voxel_updates = samples * m.geometry.view_count();
  report.timings.total = constructor_setup + detail::seconds_since(start);
  return report;
}

}  // namespace ivol::recon
