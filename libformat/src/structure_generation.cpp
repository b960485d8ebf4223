// Generating the four structures from a need mask (paper, section 4): full
// resolution wherever the mask says so, coarse elsewhere as each structure
// allows. Work is proportional to the mask's cells plus the bricks made, and
// the octree's subtrees are generated in parallel.
#include <algorithm>
#include <atomic>
#include <optional>
#include <stdexcept>
#include <thread>

#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/structures.hpp"
#include "octree_builder.hpp"
#include "thread_parts.hpp"

namespace ivol {
namespace {

std::uint32_t side_at(unsigned depth, unsigned level) { return 1u << (depth - level); }

class RegularStructure final : public VoxelStructure {
 public:
  explicit RegularStructure(const Dims& dims) {
    dims_ = dims;
    bricks_ = BrickList(dims_);
    bricks_.push_back(Brick{{0, 0, 0}, {1, 1, 1}, {dims[0], dims[1], dims[2]}, 0});
    finish_bricks();
  }
  StructureKind kind() const override { return StructureKind::Regular; }
  StructureMemory memory() const override { return {2 * voxel_count(), 0}; }
};

// Intervals along one axis: full resolution where any cell of the mask's
// plane needs it, else as long as allowed.
struct Interval {
  std::uint32_t start, size;
};

class RectilinearStructure final : public VoxelStructure {
 public:
  RectilinearStructure(const NeedMask& mask, std::uint32_t max_interval) {
    dims_ = mask.dims;
    bricks_ = BrickList(dims_);
    std::array<std::vector<Interval>, 3> axes;
    for (int a = 0; a < 3; ++a) {
      axes[a] = intervals(mask, a, max_interval);
      for (const Interval& iv : axes[a]) borders_[a].push_back(iv.start);
      borders_[a].push_back(dims_[a]);
    }
    // Bricks: runs of equal-sized intervals along each axis, crossed.
    std::array<std::vector<Interval>, 3> runs;  // start, interval size; count in run_counts
    std::array<std::vector<std::uint32_t>, 3> run_counts;
    for (int a = 0; a < 3; ++a) {
      for (const Interval& iv : axes[a]) {
        if (!runs[a].empty() && runs[a].back().size == iv.size)
          ++run_counts[a].back();
        else
          runs[a].push_back(iv), run_counts[a].push_back(1);
      }
    }
    for (std::size_t k = 0; k < runs[2].size(); ++k)
      for (std::size_t j = 0; j < runs[1].size(); ++j)
        for (std::size_t i = 0; i < runs[0].size(); ++i)
          bricks_.push_back(Brick{{runs[0][i].start, runs[1][j].start, runs[2][k].start},
                                  {runs[0][i].size, runs[1][j].size, runs[2][k].size},
                                  {run_counts[0][i], run_counts[1][j], run_counts[2][k]},
                                  0});
    finish_bricks();
  }
  StructureKind kind() const override { return StructureKind::Rectilinear; }
  // 16-bit values; borders as 32-bit positions (three lists of n + 1).
  StructureMemory memory() const override {
    return {2 * voxel_count(), 4 * (borders_[0].size() + borders_[1].size() + borders_[2].size())};
  }

 private:
  static std::vector<Interval> intervals(const NeedMask& mask, int axis, std::uint32_t max_interval) {
    const std::uint32_t n = mask.cells[axis];
    std::vector<std::uint8_t> needed(n, 0);
    const Dims& c = mask.cells;
    for (std::uint32_t k = 0; k < c[2]; ++k)
      for (std::uint32_t j = 0; j < c[1]; ++j)
        for (std::uint32_t i = 0; i < c[0]; ++i)
          if (mask.at(i, j, k)) needed[axis == 0 ? i : axis == 1 ? j : k] = 1;
    std::vector<Interval> out;
    const std::uint32_t size = mask.dims[axis];
    std::uint32_t cell = 0;
    while (cell < n) {
      std::uint32_t end = cell;
      while (end < n && needed[end] == needed[cell]) ++end;
      const std::uint32_t from = cell * mask.factor;
      const std::uint32_t to = std::min(size, end * mask.factor);
      if (needed[cell]) {
        out.push_back({from, 1});
        for (std::uint32_t x = from + 1; x < to; ++x) out.push_back({x, 1});
      } else {
        for (std::uint32_t x = from; x < to; x += max_interval) out.push_back({x, std::min(max_interval, to - x)});
      }
      cell = end;
    }
    return out;
  }
};

class NestedStructure final : public VoxelStructure {
 public:
  NestedStructure(const NeedMask& mask, std::uint32_t cell) {
    dims_ = mask.dims;
    bricks_ = BrickList(dims_);
    nested_cell_ = cell;
    const Dims cells{(dims_[0] + cell - 1) / cell, (dims_[1] + cell - 1) / cell, (dims_[2] + cell - 1) / cell};
    cells_ = ivol::voxel_count(cells);
    for (std::uint32_t k = 0; k < cells[2]; ++k)
      for (std::uint32_t j = 0; j < cells[1]; ++j)
        for (std::uint32_t i = 0; i < cells[0]; ++i) {
          const std::array<std::uint32_t, 3> lo{i * cell, j * cell, k * cell};
          std::array<std::uint32_t, 3> extent{};
          for (int a = 0; a < 3; ++a) extent[a] = std::min(cell, dims_[a] - lo[a]);
          if (needs(mask, lo, extent))
            bricks_.push_back(Brick{lo, {1, 1, 1}, extent, 0});
          else
            bricks_.push_back(Brick{lo, extent, {1, 1, 1}, 0});
        }
    finish_bricks();
  }
  StructureKind kind() const override { return StructureKind::Nested; }
  // 16-bit values; one 64-bit pointer to each coarse cell's first voxel.
  StructureMemory memory() const override { return {2 * voxel_count(), 8 * cells_}; }

 private:
  static bool needs(const NeedMask& mask, const std::array<std::uint32_t, 3>& lo,
                    const std::array<std::uint32_t, 3>& extent) {
    std::uint32_t a0[3], a1[3];
    for (int a = 0; a < 3; ++a) a0[a] = lo[a] / mask.factor, a1[a] = (lo[a] + extent[a] - 1) / mask.factor;
    for (std::uint32_t k = a0[2]; k <= a1[2]; ++k)
      for (std::uint32_t j = a0[1]; j <= a1[1]; ++j)
        for (std::uint32_t i = a0[0]; i <= a1[0]; ++i)
          if (mask.at(i, j, k)) return true;
    return false;
  }
  std::uint64_t cells_ = 0;
};

// OR and AND pyramids of the need mask: does a node need full resolution
// somewhere (any), everywhere (all)?
class NeedPyramid {
 public:
  explicit NeedPyramid(const NeedMask& mask) : mask_(mask) {
    depth_ = depth_for(mask.dims);
    cell_level_ = depth_;
    while (cell_level_ > 0 && side_at(depth_, cell_level_) < mask.factor) --cell_level_;
    any_.resize(cell_level_ + 1);
    all_.resize(cell_level_ + 1);
    dims_.resize(cell_level_ + 1);
    dims_[cell_level_] = mask.cells;
    // The cell level is the mask itself (read through at(), packed or not),
    // not a copy: two copies of a byte mask were 2 bytes a cell.
    for (int l = static_cast<int>(cell_level_) - 1; l >= 0; --l) {
      const Dims& f = dims_[l + 1];
      const Dims d{(f[0] + 1) / 2, (f[1] + 1) / 2, (f[2] + 1) / 2};
      dims_[l] = d;
      any_[l].assign(voxel_count(d), 0);
      all_[l].assign(voxel_count(d), 1);
      const bool from_mask = static_cast<unsigned>(l) + 1 == cell_level_;
      for (std::uint32_t k = 0; k < f[2]; ++k)
        for (std::uint32_t j = 0; j < f[1]; ++j)
          for (std::uint32_t i = 0; i < f[0]; ++i) {
            const std::uint64_t child = (std::uint64_t{k} * f[1] + j) * f[0] + i;
            const std::uint64_t parent = (std::uint64_t{k / 2} * d[1] + j / 2) * d[0] + i / 2;
            const std::uint8_t need = from_mask ? (mask.at(child) ? 1 : 0) : any_[l + 1][child];
            const std::uint8_t every = from_mask ? need : all_[l + 1][child];
            any_[l][parent] |= need;
            all_[l][parent] &= every;
          }
    }
  }
  unsigned depth() const { return depth_; }
  unsigned cell_level() const { return cell_level_; }
  // For nodes at levels <= cell_level (coarser than or as large as a cell).
  bool any(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return get(any_, std::min(level, cell_level_), i, j, k, level);
  }
  bool all(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return get(all_, std::min(level, cell_level_), i, j, k, level);
  }

 private:
  bool get(const std::vector<std::vector<std::uint8_t>>& p, unsigned at, std::uint32_t i, std::uint32_t j,
           std::uint32_t k, unsigned level) const {
    const unsigned shift = level - at;  // finer nodes than cells share their cell's answer
    i >>= shift, j >>= shift, k >>= shift;
    const Dims& d = dims_[at];
    if (i >= d[0] || j >= d[1] || k >= d[2]) return false;
    const std::uint64_t n = (std::uint64_t{k} * d[1] + j) * d[0] + i;
    return at == cell_level_ ? mask_.at(n) : p[at][n] != 0;
  }
  const NeedMask& mask_;
  unsigned depth_ = 0;
  unsigned cell_level_ = 0;
  std::vector<std::vector<std::uint8_t>> any_, all_;
  std::vector<Dims> dims_;
};

class OctreeStructure final : public VoxelStructure {
 public:
  OctreeStructure(const NeedMask& mask, unsigned threads) {
    dims_ = mask.dims;
    bricks_ = BrickList(dims_);
    layout_.dims = dims_;
    layout_.depth = depth_for(dims_);
    const NeedPyramid pyramid(mask);
    // Subtrees below level `split` are generated in parallel, then
    // concatenated in Morton order.
    const unsigned split = std::min(layout_.depth, 2u);
    const std::uint32_t tasks = 1u << (3 * split);
    std::vector<std::vector<PackedBrick>> parts(tasks);
    std::vector<std::uint64_t> inner(tasks, 0);
    std::atomic<std::uint32_t> next{0};
    auto work = [&] {
      for (std::uint32_t t; (t = next.fetch_add(1)) < tasks;) {
        std::uint32_t i, j, k;
        detail::morton_decode(split, t, i, j, k);
        visit(pyramid, split, i, j, k, parts[t], inner[t]);
        parts[t].shrink_to_fit();
      }
    };
    detail::run_parts(std::max(1u, threads), [&](unsigned) { work(); });
    inner_nodes_ = count_top(pyramid, 0, 0, 0, 0, split);
    // Each part freed as soon as it is copied: the bricks are held about
    // once, not twice (16 bytes each; tens of millions at 1152³, issue 23).
    std::size_t total = 0;
    for (const auto& part : parts) total += part.size();
    bricks_.reserve(total);
    for (std::uint32_t t = 0; t < tasks; ++t) {
      inner_nodes_ += inner[t];
      bricks_.append(parts[t]);
      std::vector<PackedBrick>().swap(parts[t]);
    }
    // Bricks (and so values) by their first slice, Morton order within one:
    // a reconstruction finishing slabs along z then finds the values it can
    // write and forget next to each other (StructureValueWindow).
    bricks_.sort_by_first_slice();
    finish_bricks();
  }
  StructureKind kind() const override { return StructureKind::Octree; }
  // The pointer-packed octree: a node word per inner node, a 16-bit value
  // per node (leaves and inner averages).
  StructureMemory memory() const override { return {2 * (1 + 8 * inner_nodes_), 8 * inner_nodes_}; }
  std::uint64_t inner_nodes() const { return inner_nodes_; }

 private:
  // Every octree brick is a node clipped to the volume: a cube record.
  PackedBrick cube(const Brick& b) const {
    const std::optional<PackedBrick> record = bricks_.cube_record(b);
    if (!record) throw std::logic_error("octree: a brick that is not a clipped node");
    return *record;
  }

  // Fully needed subtrees up to this side become one brick of fine voxels.
  static constexpr std::uint32_t kMaxFineBrick = 16;

  std::uint64_t weight_extent(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k,
                              std::array<std::uint32_t, 3>& lo, std::array<std::uint32_t, 3>& extent) const {
    const std::uint32_t s = side_at(layout_.depth, level);
    const std::uint32_t c[3] = {i, j, k};
    std::uint64_t w = 1;
    for (int a = 0; a < 3; ++a) {
      lo[a] = c[a] * s;
      extent[a] = lo[a] >= dims_[a] ? 0 : std::min(s, dims_[a] - lo[a]);
      w *= extent[a];
    }
    return w;
  }

  // Inner nodes of a fully subdivided subtree clipped to the volume: at every
  // level above the voxels, the nodes that hold a voxel.
  static std::uint64_t full_subtree_inner(const std::array<std::uint32_t, 3>& extent, std::uint32_t side) {
    std::uint64_t n = 0;
    for (std::uint32_t s = side; s > 1; s /= 2)
      n += std::uint64_t{(extent[0] + s - 1) / s} * ((extent[1] + s - 1) / s) * ((extent[2] + s - 1) / s);
    return n;
  }

  void visit(const NeedPyramid& p, unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k,
             std::vector<PackedBrick>& out, std::uint64_t& inner) const {
    std::array<std::uint32_t, 3> lo{}, extent{};
    if (weight_extent(level, i, j, k, lo, extent) == 0) return;  // padding
    const std::uint32_t s = side_at(layout_.depth, level);
    if (!p.any(level, i, j, k)) {
      out.push_back(cube(Brick{lo, extent, {1, 1, 1}, 0}));  // one coarse leaf
      return;
    }
    if (s == 1 || (s <= kMaxFineBrick && p.all(level, i, j, k))) {
      out.push_back(cube(Brick{lo, {1, 1, 1}, extent, 0}));
      inner += full_subtree_inner(extent, s);
      return;
    }
    ++inner;
    for (unsigned c = 0; c < 8; ++c)
      visit(p, level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u), out, inner);
  }

  // Inner nodes above the split: those that need subdividing.
  std::uint64_t count_top(const NeedPyramid& p, unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k,
                          unsigned split) const {
    if (level == split) return 0;
    std::array<std::uint32_t, 3> lo{}, extent{};
    if (weight_extent(level, i, j, k, lo, extent) == 0 || !p.any(level, i, j, k)) return 0;
    std::uint64_t n = 1;
    for (unsigned c = 0; c < 8; ++c)
      n += count_top(p, level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u), split);
    return n;
  }

  VolumeLayout layout_;
  std::uint64_t inner_nodes_ = 0;
};

}  // namespace

NeedMask need_mask_from_low_resolution(const float* low, const Dims& low_dims, std::uint32_t factor,
                                       const Dims& full_dims, float threshold, unsigned margin_voxels) {
  if (factor == 0 || (factor & (factor - 1)) != 0)
    throw Error(ErrorClass::InvalidArgument, "need mask: the resolution factor must be a power of two");
  for (int a = 0; a < 3; ++a)
    if (low_dims[a] != (full_dims[a] + factor - 1) / factor)
      throw Error(ErrorClass::InvalidArgument, "need mask: the low-resolution grid must be ceil(full / factor)");
  NeedMask mask;
  mask.dims = full_dims;
  mask.factor = factor;
  mask.cells = low_dims;
  mask.need = threshold_keep_mask(low, low_dims, threshold, (margin_voxels + factor - 1) / factor);
  return mask;
}

std::unique_ptr<VoxelStructure> generate_structure(StructureKind kind, const NeedMask& mask,
                                                   const GenerationOptions& options) {
  const unsigned threads = options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  switch (kind) {
    case StructureKind::Regular:
      return std::make_unique<RegularStructure>(mask.dims);
    case StructureKind::Rectilinear:
      return std::make_unique<RectilinearStructure>(mask, std::max(1u, options.rectilinear_max_interval));
    case StructureKind::Nested: {
      const std::uint32_t cell = options.nested_cell;
      if (cell == 0 || (cell & (cell - 1)) != 0)
        throw Error(ErrorClass::InvalidArgument, "nested grid: the cell size must be a power of two");
      return std::make_unique<NestedStructure>(mask, cell);
    }
    case StructureKind::Octree:
      return std::make_unique<OctreeStructure>(mask, threads);
    case StructureKind::Bricked:  // the same cells as the regular grid, stored otherwise (BrickedGridWriter)
      break;
  }
  throw Error(ErrorClass::InvalidArgument,
              std::string(structure_name(kind)) + ": no structure of this kind is generated");
}

}  // namespace ivol
