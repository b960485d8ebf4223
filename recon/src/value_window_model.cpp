#include "value_window_model.hpp"

#include <algorithm>

#include "ivol/structure_stream.hpp"

namespace ivol::recon::detail {
namespace {

constexpr std::uint64_t kPage = StructureValueWindow::kPageValues;
constexpr std::uint64_t kTallEntryBytes = 40;  // as structure_value_window.cpp counts a tall voxel

// Counts per slice into "how many below z" (prefix sums over slices).
void accumulate(std::vector<std::uint64_t>& v) {
  std::uint64_t sum = 0;
  for (std::uint64_t& x : v) sum += x, x = sum;
}

}  // namespace

ValueWindowModel::ValueWindowModel(const VoxelStructure& structure) {
  const Dims& dims = structure.dims();
  const std::size_t nz = dims[2];
  const std::uint64_t page_count = (structure.voxel_count() + kPage - 1) / kPage;
  std::vector<std::uint32_t> page_lo(page_count, UINT32_MAX), page_hi(page_count, 0);
  // Counts at index z + 1, so that after the prefix sums [z] counts those below z.
  pages_from_.assign(nz + 2, 0);
  pages_to_.assign(nz + 2, 0);
  tall_from_.assign(nz + 2, 0);
  tall_to_.assign(nz + 2, 0);
  const BrickList& bricks = structure.bricks();
  for (const Brick& b : bricks) {
    const auto end =
        static_cast<std::uint32_t>(std::min<std::uint64_t>(nz, b.origin[2] + std::uint64_t{b.voxel[2]} * b.count[2]));
    const bool lone = b.count[0] == 1 && b.count[1] == 1 && b.count[2] == 1;
    if (lone && b.voxel[2] > StructureValueWindow::kTallVoxel) {
      ++tall_from_[b.origin[2] + 1];
      ++tall_to_[end];
      continue;
    }
    // A brick's values are z-major: the part in one page spans the slices
    // of its first and its last value.
    const std::uint64_t plane = std::uint64_t{b.count[0]} * b.count[1];
    const std::uint64_t last_value = b.first_value + b.voxel_count();
    for (std::uint64_t p = b.first_value / kPage; p * kPage < last_value; ++p) {
      const std::uint64_t first = std::max(b.first_value, p * kPage);
      const std::uint64_t last = std::min(last_value, (p + 1) * kPage) - 1;
      const auto z0 = static_cast<std::uint32_t>(b.origin[2] + (first - b.first_value) / plane * b.voxel[2]);
      const auto z1 = static_cast<std::uint32_t>(
          std::min<std::uint64_t>(nz, b.origin[2] + ((last - b.first_value) / plane + 1) * b.voxel[2]));
      page_lo[p] = std::min(page_lo[p], z0);
      page_hi[p] = std::max(page_hi[p], z1);
    }
  }
  for (std::uint64_t p = 0; p < page_count; ++p) {
    if (page_lo[p] == UINT32_MAX) continue;
    ++pages_from_[page_lo[p] + 1];
    ++pages_to_[page_hi[p]];
  }
  for (auto* v : {&pages_from_, &tall_from_, &pages_to_, &tall_to_}) accumulate(*v);
}

std::uint64_t ValueWindowModel::bytes(std::uint32_t lo, std::uint32_t hi) const {
  const std::size_t last = pages_from_.size() - 2;
  hi = static_cast<std::uint32_t>(std::min<std::size_t>(hi, last));
  lo = std::min(lo, hi);
  // Those ending at or below lo also start below hi, so the difference counts the overlap.
  const std::uint64_t pages = pages_from_[hi] - pages_to_[lo];
  const std::uint64_t tall = tall_from_[hi] - tall_to_[lo];
  return pages * kPage * sizeof(float) + tall * kTallEntryBytes;
}

}  // namespace ivol::recon::detail
