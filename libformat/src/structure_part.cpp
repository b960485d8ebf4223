// Part of a structure along z, for reconstructing and building it in pieces
// (a distributed run's slabs, docs/distributed.md), and the octree writer's
// slabs filled from a structure's bricks.
#include <algorithm>
#include <array>
#include <stdexcept>

#include "brick_rows.hpp"
#include "ivol/structure_stream.hpp"
#include "ivol/structures.hpp"

namespace ivol {

namespace {

std::uint64_t brick_end(const Brick& b) { return b.origin[2] + std::uint64_t{b.voxel[2]} * b.count[2]; }

bool meets(const Brick& b, const SliceRange& range) { return b.origin[2] < range.end && brick_end(b) > range.first; }

class StructurePart final : public VoxelStructure {
 public:
  StructurePart(const VoxelStructure& whole, const std::vector<SliceRange>& ranges) : kind_(whole.kind()) {
    for (std::size_t n = 1; n < ranges.size(); ++n)
      if (ranges[n].first < ranges[n - 1].end)
        throw std::invalid_argument("structure_part: the slice ranges must be increasing and disjoint");
    dims_ = whole.dims();
    bricks_ = BrickList(dims_);
    borders_ = whole.borders();
    nested_cell_ = whole.nested_cell();
    // Bricks come by their first slice, so a brick meets the ranges from the
    // first one that does not end at or below its first slice. A brick of
    // fine voxels is cut to the slices of each range it meets (a fine
    // voxel's value is its own); a coarse voxel is taken whole, once.
    std::size_t from = 0;
    for (Brick b : whole.bricks()) {
      while (from < ranges.size() && ranges[from].end <= b.origin[2]) ++from;
      const bool fine = b.voxel == std::array<std::uint32_t, 3>{1, 1, 1};
      const Brick whole_brick = b;
      for (std::size_t r = from; r < ranges.size() && ranges[r].first < brick_end(whole_brick); ++r) {
        if (!meets(whole_brick, ranges[r])) continue;
        if (!fine) {
          bricks_.push_back(b);
          break;
        }
        b.origin[2] = std::max(whole_brick.origin[2], ranges[r].first);
        b.count[2] = static_cast<std::uint32_t>(std::min<std::uint64_t>(brick_end(whole_brick), ranges[r].end) -
                                                b.origin[2]);
        bricks_.push_back(b);
      }
    }
    bricks_.sort_by_first_slice();  // the pieces of a cut brick come later
    finish_bricks();
  }
  StructureKind kind() const override { return kind_; }
  // The part's own values and brick records; the structure's bookkeeping
  // (node words, borders, cell words) belongs to the whole.
  StructureMemory memory() const override { return {2 * voxel_count(), bricks_.memory_bytes()}; }

 private:
  StructureKind kind_;
};

}  // namespace

std::unique_ptr<VoxelStructure> structure_part(const VoxelStructure& structure, const std::vector<SliceRange>& ranges) {
  const auto& bricks = structure.bricks();
  for (std::size_t n = 1; n < bricks.size(); ++n)
    if (bricks[n].origin[2] < bricks[n - 1].origin[2])
      throw std::logic_error("structure_part: the structure's bricks are not ordered by their first slice");
  return std::make_unique<StructurePart>(structure, ranges);
}

OctreeSlabFiller::OctreeSlabFiller(const VoxelStructure& structure) : structure_(structure) {
  const auto& bricks = structure.bricks();
  by_first_slice_.resize(bricks.size());
  for (std::uint32_t n = 0; n < by_first_slice_.size(); ++n) by_first_slice_[n] = n;
  std::stable_sort(by_first_slice_.begin(), by_first_slice_.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return bricks[a].origin[2] < bricks[b].origin[2]; });
}

void OctreeSlabFiller::fill(std::uint32_t z0, std::uint32_t z1, const StructureValueSource& values, float* samples,
                            std::uint8_t* keep) {
  if (z0 < last_end_) throw std::logic_error("OctreeSlabFiller: slabs must come in increasing z");
  last_end_ = z1;
  const Dims& dims = structure_.dims();
  const auto& bricks = structure_.bricks();
  while (next_ < by_first_slice_.size() && bricks[by_first_slice_[next_]].origin[2] < z1)
    open_.push_back(by_first_slice_[next_++]);
  for (std::size_t n = 0; n < open_.size();) {
    const std::uint32_t brick = open_[n];
    const Brick b = bricks[brick];
    const std::uint8_t fine = b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1 ? 1 : 0;
    detail::for_each_brick_row(
        b, dims, z0, z1, [&](std::uint64_t v, std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint64_t z) {
          const std::uint64_t row = ((z - z0) * dims[1] + y) * dims[0];
          std::fill(samples + row + x0, samples + row + x1, values.value(brick, v));
          std::fill(keep + row + x0, keep + row + x1, fine);
        });
    if (brick_end(b) <= z1) {  // done with this brick
      open_[n] = open_.back();
      open_.pop_back();
    } else {
      ++n;
    }
  }
}

}  // namespace ivol
