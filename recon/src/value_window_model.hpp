// How much a StructureValueWindow holds while a structure is reconstructed
// slab by slab and written behind it (issue 23: the value window bounded by
// its share of --memory): its pages of values and its tall lone voxels, as
// the window keeps them, counted per range of slices.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/structures.hpp"

namespace ivol::recon::detail {

class ValueWindowModel {
 public:
  explicit ValueWindowModel(const VoxelStructure& structure);
  // Bytes held once the values of voxels starting below slice `hi` may have
  // been written and everything ending at or below `lo` released (lo < hi):
  // every page (and tall voxel) whose values start below hi and end above lo.
  std::uint64_t bytes(std::uint32_t lo, std::uint32_t hi) const;

 private:
  // [z]: pages (tall voxels) starting below z, and ending at or below z.
  std::vector<std::uint64_t> pages_from_, pages_to_, tall_from_, tall_to_;
};

}  // namespace ivol::recon::detail
