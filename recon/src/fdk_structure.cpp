// FDK straight into an inhomogeneous structure (Betz et al., section 5):
// only the structure's voxels are backprojected, each at its own size.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

#include "fdk_session.hpp"
#include "ivol/error.hpp"
#include "ivol/structure_stream.hpp"
#include "value_window_model.hpp"

namespace ivol::recon {
namespace {

static_assert(sizeof(FineTask) == 32, "FineTask must match kernels/recon_layout.h");
static_assert(sizeof(CoarseTask) == 32, "CoarseTask must match kernels/recon_layout.h");

constexpr std::uint32_t kDepth = IVOL_BACKPROJECT_DEPTH;
constexpr std::uint32_t kRun = IVOL_FINE_RUN;

constexpr std::uint32_t kNone = UINT32_MAX;

// Where a block task's sample points lie in its brick, or in a stack of two.
struct BlockRef {
  std::uint32_t brick;
  std::uint32_t mi, mj, mk;     // the block's first sample on the brick's lattice
  std::uint32_t upper = kNone;  // the brick stacked on top, whose points follow along k
  std::uint32_t split = 0;      // the lower brick's points along k
};

// Sample points per voxel along an axis: the voxel's centre when it is one
// voxel wide, else its two halves' centres (with the other axes: octants).
std::uint32_t points_per_voxel(std::uint32_t edge) { return edge > 1 ? 2 : 1; }

bool is_lone(const Brick& b) { return b.count[0] == 1 && b.count[1] == 1 && b.count[2] == 1; }
bool is_fine(const Brick& b) { return b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1; }

// Two full-resolution bricks of the same footprint, one on top of the other,
// both thinner than a block's depth: backprojected as one brick, they fill a
// block's lanes instead of half of them (the octree's 4³ bricks along a
// surface, as a 1/4 preview's need mask makes them).
Brick stacked(const Brick& lower, const Brick& upper) {
  Brick both = lower;
  both.count[2] += upper.count[2];
  return both;
}

// A brick's sample points as blocks of kRun × kDepth points: voxel centres,
// or octant centres of voxels wider than one along an axis. Lanes per row are
// the points along i, rounded up to a power of two; the rest of a block's
// lanes take the next rows along j. A coarse voxel's points along k (two)
// always fall in one block, since kDepth is even: a voxel's value is final
// once its block's slab is delivered.
struct BrickLattice {
  std::array<std::uint32_t, 3> points{};
  std::array<double, 3> step{}, first{};
  std::uint32_t run_i = 1, rows = kRun;
  explicit BrickLattice(const Brick& b) {
    for (int a = 0; a < 3; ++a) {
      points[a] = b.count[a] * points_per_voxel(b.voxel[a]);
      step[a] = static_cast<double>(b.voxel[a]) / points_per_voxel(b.voxel[a]);
      first[a] = b.origin[a] + 0.5 * step[a] - 0.5;
    }
    while (run_i < std::min(points[0], kRun)) run_i *= 2;
    rows = kRun / run_i;
  }
  double k_of_layer(std::uint32_t mk) const { return first[2] + mk * step[2]; }
  // The first slice of the voxels a block layer starting at point mk samples.
  std::uint32_t z_of_layer(const Brick& b, std::uint32_t mk) const {
    return b.origin[2] + mk / points_per_voxel(b.voxel[2]) * b.voxel[2];
  }
};

// A lone voxel's task: its centre, and the quarter of its edges where its
// octants' centres lie.
CoarseTask lone_task(const Brick& b) {
  CoarseTask t{};
  t.i = static_cast<float>(b.origin[0] + 0.5 * b.voxel[0] - 0.5);
  t.j = static_cast<float>(b.origin[1] + 0.5 * b.voxel[1] - 0.5);
  t.k = static_cast<float>(b.origin[2] + 0.5 * b.voxel[2] - 0.5);
  t.quarter_i = 0.25F * static_cast<float>(b.voxel[0]);
  t.quarter_j = 0.25F * static_cast<float>(b.voxel[1]);
  t.quarter_k = 0.25F * static_cast<float>(b.voxel[2]);
  return t;
}

// Which slab a task belongs to: the one holding its first sample along k.
struct SlabOf {
  std::uint32_t slices;
  std::size_t count;
  std::size_t operator()(double k) const {
    return std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 0.0)) / slices, count - 1);
  }
};

// What is known of each slab before any task is made: the bricks with tasks
// in it, how far along k its samples reach, and the lowest first slice of
// its voxels (a voxel's value is final once its slab is delivered).
struct SlabIndex {
  std::vector<std::vector<std::uint32_t>> bricks;
  std::vector<std::uint32_t> upper;    // per brick: the brick stacked on it, or kNone
  std::vector<std::uint8_t> is_upper;  // per brick: 1 if stacked on another (its tasks are that one's)
  std::vector<double> k_low, k_high;
  std::vector<std::uint32_t> z_low;
  // After slab s is delivered, every voxel starting below complete_below[s]
  // is final.
  std::vector<std::uint32_t> complete_below;
  // Per slab: its block tasks and its lone voxels, as tasks_of_slab makes
  // them (it reserves these counts, so the lists take exactly their bytes).
  std::vector<std::uint64_t> block_count, centre_count, octant_count;
  std::uint64_t task_bytes(std::size_t s) const;
  std::uint64_t stacking_peak_bytes = 0;  // the thin bricks' lookup, freed after stacking
  std::uint64_t bytes() const {
    std::uint64_t n = bricks.capacity() * sizeof(bricks[0]) + upper.capacity() * 4 + is_upper.capacity() +
                      (k_low.capacity() + k_high.capacity()) * 8 + (z_low.capacity() + complete_below.capacity()) * 4;
    for (const auto& list : bricks) n += list.capacity() * 4;
    n += (block_count.capacity() + centre_count.capacity() + octant_count.capacity()) * 8;
    return std::max(n, stacking_peak_bytes + (upper.capacity() * 4 + is_upper.capacity()));
  }
};

// Pairs thin full-resolution bricks with the one on top of them (bricks are
// visited bottom first in every structure's order, by their first slice).
void stack_thin_bricks(const BrickList& bricks, SlabIndex& x) {
  x.upper.assign(bricks.size(), kNone);
  x.is_upper.assign(bricks.size(), 0);
  auto key = [](std::uint64_t i, std::uint64_t j, std::uint64_t k) { return (k << 42) | (j << 21) | i; };
  auto thin = [](const Brick& b) { return is_fine(b) && b.count[2] < kDepth; };
  // Thin bricks by their corner, sorted for lookup: 16 bytes each, where a
  // hash map took about 40 (tens of millions of them at 1152³, issue 23).
  std::vector<std::pair<std::uint64_t, std::uint32_t>> thin_at;
  thin_at.reserve(static_cast<std::size_t>(std::count_if(bricks.begin(), bricks.end(), thin)));
  for (std::uint32_t n = 0; n < bricks.size(); ++n)
    if (thin(bricks[n])) thin_at.emplace_back(key(bricks[n].origin[0], bricks[n].origin[1], bricks[n].origin[2]), n);
  x.stacking_peak_bytes = thin_at.capacity() * sizeof(thin_at[0]);
  std::sort(thin_at.begin(), thin_at.end());
  for (std::uint32_t n = 0; n < bricks.size(); ++n) {
    const Brick& b = bricks[n];
    if (!thin(b) || x.is_upper[n] || x.upper[n] != kNone) continue;
    const std::uint64_t above = key(b.origin[0], b.origin[1], std::uint64_t{b.origin[2]} + b.count[2]);
    const auto found = std::lower_bound(thin_at.begin(), thin_at.end(), std::make_pair(above, std::uint32_t{0}));
    if (found == thin_at.end() || found->first != above) continue;
    const std::uint32_t u = found->second;
    const Brick& top = bricks[u];
    if (x.is_upper[u] || x.upper[u] != kNone || top.count[0] != b.count[0] || top.count[1] != b.count[1] ||
        b.count[2] + top.count[2] > kDepth)
      continue;
    x.upper[n] = u;
    x.is_upper[u] = 1;
  }
}

SlabIndex index_slabs(const VoxelStructure& structure, const SlabOf& slab_of) {
  SlabIndex x;
  const std::size_t count = slab_of.count;
  x.bricks.resize(count);
  x.k_low.assign(count, 1e300);
  x.k_high.assign(count, -1e300);
  x.z_low.assign(count, UINT32_MAX);
  x.block_count.assign(count, 0);
  x.centre_count.assign(count, 0);
  x.octant_count.assign(count, 0);
  const BrickList& bricks = structure.bricks();
  stack_thin_bricks(bricks, x);
  for (std::uint32_t index = 0; index < bricks.size(); ++index) {
    if (x.is_upper[index]) continue;
    const Brick b = x.upper[index] == kNone ? bricks[index] : stacked(bricks[index], bricks[x.upper[index]]);
    auto note = [&](std::size_t s, double k_low, double k_high, std::uint32_t z) {
      if (x.bricks[s].empty() || x.bricks[s].back() != index) x.bricks[s].push_back(index);
      x.k_low[s] = std::min(x.k_low[s], k_low);
      x.k_high[s] = std::max(x.k_high[s], k_high);
      x.z_low[s] = std::min(x.z_low[s], z);
    };
    if (is_lone(b)) {
      const CoarseTask t = lone_task(b);
      const std::size_t s = slab_of(t.k);
      note(s, t.k - t.quarter_k, t.k + t.quarter_k, b.origin[2]);
      ++(std::max({b.voxel[0], b.voxel[1], b.voxel[2]}) <= 2 ? x.centre_count : x.octant_count)[s];
      continue;
    }
    const BrickLattice lattice(b);
    for (std::uint32_t mk = 0; mk < lattice.points[2]; mk += kDepth) {
      const double k = lattice.k_of_layer(mk);
      const std::size_t s = slab_of(k);
      note(s, k, k + (kDepth - 1) * lattice.step[2], lattice.z_of_layer(b, mk));
      x.block_count[s] += std::uint64_t{(lattice.points[1] + lattice.rows - 1) / lattice.rows} *
                          ((lattice.points[0] + lattice.run_i - 1) / lattice.run_i);
    }
  }
  x.complete_below.assign(count, structure.dims()[2]);
  std::uint32_t lowest_later = structure.dims()[2];
  for (std::size_t s = count; s-- > 0;) {
    x.complete_below[s] = lowest_later;
    lowest_later = std::min(lowest_later, x.z_low[s]);
  }
  return x;
}

// A slab's tasks and where their sums go.
struct SlabTasks {
  static constexpr std::uint64_t kBlockBytes = sizeof(FineTask) + sizeof(BlockRef);
  static constexpr std::uint64_t kLoneBytes = sizeof(CoarseTask) + sizeof(std::uint32_t);
  std::vector<FineTask> blocks;
  std::vector<BlockRef> block_refs;
  std::vector<CoarseTask> centres;  // lone voxels up to two wide: one sample
  std::vector<CoarseTask> octants;  // wider lone voxels: eight
  std::vector<std::uint32_t> centre_brick;
  std::vector<std::uint32_t> octant_brick;
  std::uint64_t bytes() const {
    return blocks.capacity() * sizeof(FineTask) + block_refs.capacity() * sizeof(BlockRef) +
           (centres.capacity() + octants.capacity()) * sizeof(CoarseTask) +
           (centre_brick.capacity() + octant_brick.capacity()) * 4;
  }
  std::uint64_t samples() const {
    std::uint64_t n = centres.size() + 8 * octants.size();
    for (const FineTask& f : blocks) n += std::uint64_t{f.count & 0xFF} * ((f.count >> 8) & 0xFF) * (f.count >> 16);
    return n;
  }
};

std::uint64_t SlabIndex::task_bytes(std::size_t s) const {
  return block_count[s] * SlabTasks::kBlockBytes + (centre_count[s] + octant_count[s]) * SlabTasks::kLoneBytes;
}

// The most the task lists of the slabs in flight hold at once: a slab being
// made and one waiting per device, and the one being delivered.
std::uint64_t tasks_in_flight_peak(const SlabIndex& index, std::size_t devices) {
  std::vector<std::uint64_t> bytes;
  for (std::size_t s = 0; s < index.block_count.size(); ++s) bytes.push_back(index.task_bytes(s));
  const std::size_t in_flight = std::min(bytes.size(), 2 * devices + 1);
  std::partial_sort(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(in_flight), bytes.end(),
                    std::greater<>());
  std::uint64_t sum = 0;
  for (std::size_t n = 0; n < in_flight; ++n) sum += bytes[n];
  return sum;
}

SlabTasks tasks_of_slab(const VoxelStructure& structure, const SlabIndex& index, const SlabOf& slab_of,
                        std::size_t slab) {
  SlabTasks s;
  s.blocks.reserve(index.block_count[slab]);
  s.block_refs.reserve(index.block_count[slab]);
  s.centres.reserve(index.centre_count[slab]);
  s.centre_brick.reserve(index.centre_count[slab]);
  s.octants.reserve(index.octant_count[slab]);
  s.octant_brick.reserve(index.octant_count[slab]);
  const BrickList& bricks = structure.bricks();
  for (std::uint32_t n : index.bricks[slab]) {
    const std::uint32_t upper = index.upper[n];
    const Brick b = upper == kNone ? bricks[n] : stacked(bricks[n], bricks[upper]);
    // Lone voxels, coarse ones and the single full-resolution voxels an
    // octree leaves at the object's edge, take a work-item each: in a block
    // they would fill one of its 128 lanes. (A fine one's centre sample goes
    // through the dense kernel's arithmetic, so it keeps its bits.)
    if (is_lone(b)) {
      const CoarseTask t = lone_task(b);
      if (std::max({b.voxel[0], b.voxel[1], b.voxel[2]}) <= 2) {
        s.centres.push_back(t);
        s.centre_brick.push_back(n);
      } else {
        s.octants.push_back(t);
        s.octant_brick.push_back(n);
      }
      continue;
    }
    const BrickLattice lattice(b);
    for (std::uint32_t mk = 0; mk < lattice.points[2]; mk += kDepth) {
      const double k = lattice.k_of_layer(mk);
      if (slab_of(k) != slab) continue;
      for (std::uint32_t mj = 0; mj < lattice.points[1]; mj += lattice.rows)
        for (std::uint32_t mi = 0; mi < lattice.points[0]; mi += lattice.run_i) {
          const std::uint32_t along_i = std::min(lattice.run_i, lattice.points[0] - mi);
          const std::uint32_t along_j = std::min(lattice.rows, lattice.points[1] - mj);
          const std::uint32_t along_k = std::min(kDepth, lattice.points[2] - mk);
          FineTask t{};
          t.i = static_cast<float>(lattice.first[0] + mi * lattice.step[0]);
          t.j = static_cast<float>(lattice.first[1] + mj * lattice.step[1]);
          t.k = static_cast<float>(k);
          t.step_i = static_cast<float>(lattice.step[0]);
          t.step_j = static_cast<float>(lattice.step[1]);
          t.step_k = static_cast<float>(lattice.step[2]);
          t.run_i = lattice.run_i;
          t.count = along_i | (along_j << 8) | (along_k << 16);
          s.blocks.push_back(t);
          s.block_refs.push_back(BlockRef{n, mi, mj, mk, upper, bricks[n].count[2]});
        }
    }
  }
  return s;
}

// Puts a slab's sums into the structure's values: a full-resolution voxel
// takes its one sum as it is, a coarse one the mean of its points.
void deliver(const VoxelStructure& structure, const SlabTasks& t, const std::vector<float>& sums,
             StructureValueWindow& values) {
  const BrickList& bricks = structure.bricks();
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
      // A stack's upper points go to the upper brick (same footprint, fine).
      const bool up = ref.upper != kNone && ref.mk + d >= ref.split;
      const std::uint32_t brick = up ? ref.upper : ref.brick;
      const std::uint64_t first = up ? bricks[ref.upper].first_value : b.first_value;
      const std::uint32_t mk = up ? ref.mk + d - ref.split : ref.mk + d;
      for (std::uint32_t y = 0; y < along_j; ++y) {
        const std::uint64_t base = first + mk / per_k * plane + (ref.mj + y) / per_j * row;
        for (std::uint32_t x = 0; x < along_i; ++x) {
          float& value = values.at(brick, base + (ref.mi + x) / per_i);
          const float sum = from[y * task.run_i + x];
          value = fine ? sum : value + weight * sum;
        }
      }
    }
  }
  std::size_t next = t.blocks.size() * kDepth * kRun;
  for (std::uint32_t brick : t.centre_brick) values.at(brick, bricks[brick].first_value) = sums[next++];
  for (std::uint32_t brick : t.octant_brick) values.at(brick, bricks[brick].first_value) = sums[next++];
}

detail::RowBand band_for(const ScanGeometry& geometry, const VolumeGrid& grid, const SlabIndex& index, std::size_t s) {
  if (index.bricks[s].empty()) return {};
  const double nz = grid.size[2];
  const auto k0 = static_cast<std::uint32_t>(std::clamp(std::floor(index.k_low[s]), 0.0, nz - 1));
  const auto k1 = static_cast<std::uint32_t>(std::clamp(std::ceil(index.k_high[s]) + 1.0, 1.0, nz));
  return detail::rows_for_slab(geometry, grid, k0, std::max(k1, k0 + 1));
}

// The most the value window holds over a reconstruction in these slabs:
// after slab s is delivered and before the writer catches up, it holds the
// voxels from where the writer last released (the last whole writer slab
// below what slab s − 1 completed) up to those slab s and the slabs before
// it wrote (starting below their highest sample's slice + 1).
std::uint64_t value_window_peak(const detail::ValueWindowModel& model, const SlabIndex& index,
                                std::uint32_t writer_slab_slices, std::uint32_t depth) {
  std::uint64_t peak = 0;
  std::uint32_t hi = 0;
  for (std::size_t s = 0; s < index.bricks.size(); ++s) {
    if (index.bricks[s].empty()) continue;
    const std::uint32_t completed = s == 0 ? 0 : index.complete_below[s - 1];
    const std::uint32_t lo = writer_slab_slices > 1 ? completed / writer_slab_slices * writer_slab_slices : completed;
    hi = std::max(
        hi, static_cast<std::uint32_t>(std::clamp(std::ceil(index.k_high[s]) + 1.0, 1.0, static_cast<double>(depth))));
    peak = std::max(peak, model.bytes(lo, hi));
  }
  return peak;
}

}  // namespace

FdkReport FdkReconstructor::reconstruct_structure(const VolumeGrid& grid, const VoxelStructure& structure,
                                                  StructureValueWindow& values, const StructureProgress& progress,
                                                  const ValueWindowBound& window) {
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
  std::uint32_t slices = plan.slices;
  std::uint64_t window_bytes = 0;
  std::uint64_t tasks_bytes = 0;
  SlabOf slab_of{slices, (grid.size[2] + slices - 1) / slices};
  SlabIndex index = index_slabs(structure, slab_of);
  if (window.memory_limit > 0) {
    // Thinner slabs until the values in flight fit their share.
    const detail::ValueWindowModel model(structure);
    while (true) {
      window_bytes = value_window_peak(model, index, window.writer_slab_slices, grid.size[2]);
      tasks_bytes = tasks_in_flight_peak(index, m.devices.size());
      if (window_bytes + tasks_bytes <= window.memory_limit) break;
      if (slices == 1) {
        m.problem.grid = nullptr;
        throw Error(
            ErrorClass::LimitExceeded,
            "FDK: the structure's values and tasks in flight need " + std::to_string(window_bytes + tasks_bytes) +
                " bytes with one-slice slabs and the writer's slabs of " + std::to_string(window.writer_slab_slices) +
                " slices, over their memory budget of " + std::to_string(window.memory_limit) + " bytes");
      }
      slices = std::max<std::uint32_t>(1, slices / 2);
      slab_of = SlabOf{slices, (grid.size[2] + slices - 1) / slices};
      index = index_slabs(structure, slab_of);
    }
  }
  const std::size_t slab_count = slab_of.count;
  std::vector<detail::RowBand> bands;
  int widest = 0;
  for (std::size_t s = 0; s < slab_count; ++s) {
    bands.push_back(band_for(m.geometry, grid, index, s));
    widest = std::max(widest, bands.back().rows());
  }
  try {
    for (auto& device : m.devices) device->configure(1, widest);  // no dense slab: the task sums replace it
  } catch (const cl::Error& error) {
    m.problem.grid = nullptr;
    throw std::runtime_error("FDK: allocating device memory: " + detail::describe(error));
  }
  report.slab_count = slab_count;
  report.slab_slices = slices;
  report.value_window_model_bytes = window_bytes;
  report.slab_tasks_model_bytes = tasks_in_flight_peak(index, m.devices.size());
  report.device_bytes_per_slab = plan.bytes;
  const std::vector<detail::DeviceTimings> before = m.device_timings();
  const double constructor_setup = m.setup_seconds;
  m.setup_seconds = 0;
  report.timings.setup = constructor_setup + detail::seconds_since(start);
  // This process's slabs' bands, in slab order: rows no later slab needs are released.
  const bool distributed = m.options.exchange && m.options.exchange->size() > 1;
  std::vector<std::size_t> position(slab_count, 0);
  std::vector<detail::RowBand> own_bands;
  for (std::size_t s = 0; s < slab_count; ++s)
    if (!distributed || m.options.exchange->owner(s, slab_count) == m.options.exchange->rank()) {
      position[s] = own_bands.size();
      own_bands.push_back(bands[s]);
    }
  detail::RowRelease release(m.filtered_rows.get(), own_bands);
  std::atomic<std::uint64_t> rows_filtered{0};

  // A slab's tasks are made by the thread that computes it and kept until the
  // slab is delivered, so only the slabs in flight hold task lists.
  std::vector<std::unique_ptr<SlabTasks>> tasks(slab_count);
  report.slab_index_bytes = index.bytes();
  std::atomic<std::uint64_t> task_bytes{0}, task_bytes_peak{0};
  auto note_tasks = [&](std::int64_t change) {
    const std::uint64_t now = task_bytes += static_cast<std::uint64_t>(change);
    for (std::uint64_t was = task_bytes_peak.load(); now > was && !task_bytes_peak.compare_exchange_weak(was, now);) {
    }
  };
  // What this process backprojected: every slab's samples, or only its own
  // slabs' when distributed (rank 0 delivers the others' too).
  std::atomic<std::uint64_t> own_samples{0};
  double delivering = 0;
  try {
    detail::for_each_slab(
        m.device_pointers(), slab_count,
        [&](detail::FdkDevice& device, std::size_t s, std::vector<float>& sums) {
          auto made = std::make_unique<SlabTasks>(tasks_of_slab(structure, index, slab_of, s));
          const auto made_bytes = static_cast<std::int64_t>(made->bytes());
          note_tasks(made_bytes);
          rows_filtered += m.filter_rows_for(device, bands[s], widest);
          device.reconstruct_tasks(bands[s], made->blocks, {&made->centres, &made->octants}, sums);
          release.done(position[s]);
          own_samples += made->samples();
          // Read by the delivering thread after the slab's hand-over (with an
          // exchange, only rank 0 delivers; the others send the sums).
          if (!m.options.exchange || m.options.exchange->rank() == 0)
            tasks[s] = std::move(made);
          else
            note_tasks(-made_bytes);
        },
        [&](std::size_t s, std::vector<float>& sums) {
          const auto delivery_start = std::chrono::steady_clock::now();
          std::unique_ptr<SlabTasks> t = std::move(tasks[s]);
          if (!t) {
            t = std::make_unique<SlabTasks>(tasks_of_slab(structure, index, slab_of, s));
            note_tasks(static_cast<std::int64_t>(t->bytes()));
          }
          deliver(structure, *t, sums, values);
          note_tasks(-static_cast<std::int64_t>(t->bytes()));
          t.reset();
          if (progress) progress(index.complete_below[s]);
          delivering += detail::seconds_since(delivery_start);
        },
        m.options.exchange.get(), slices);
  } catch (...) {
    m.problem.grid = nullptr;
    throw;
  }
  m.problem.grid = nullptr;
  m.add_timings_since(before, report.timings);
  report.rows_filtered = rows_filtered.load();
  report.slab_tasks_peak_bytes = task_bytes_peak.load();
  m.report_filtered_rows(report);
  report.timings.delivery += delivering;
  report.voxel_updates = own_samples.load() * m.geometry.view_count();
  report.timings.total = constructor_setup + detail::seconds_since(start);
  return report;
}

FdkReport FdkReconstructor::reconstruct_structure(const VolumeGrid& grid, VoxelStructure& structure) {
  StructureValueWindow window(structure, true);
  const FdkReport report = reconstruct_structure(grid, structure, window, {});
  std::vector<float>& values = structure.values();
  const BrickList& bricks = structure.bricks();
  for (std::uint32_t n = 0; n < bricks.size(); ++n)
    for (std::uint64_t v = bricks[n].first_value; v < bricks[n].first_value + bricks[n].voxel_count(); ++v)
      values[v] = window.value(n, v);
  return report;
}

}  // namespace ivol::recon
