// The structures of spec §8A (regular, rectilinear and nested grids) as a
// reader sees them: which cell covers which voxels, and which value it has.
// Internal to libformat.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "brick_grid.hpp"
#include "ivol/geometry.hpp"

namespace ivol::detail {

class GridStructure {
 public:
  // values_in_file when a salvaged file's values stream has gaps.
  static constexpr std::uint64_t kValuesUnknown = ~std::uint64_t{0};

  // Checks the borders (rectilinear) or cell words (nested) against spec
  // §8A and the number of values the file holds; throws Error(Malformed).
  GridStructure(const VolumeLayout& layout, std::vector<std::uint32_t> borders, std::vector<std::uint64_t> cells,
                std::uint64_t values_in_file, const std::string& where);

  // Calls visit(region, value index) for every cell meeting `box` (full
  // resolution), with `region` the part of the box it covers.
  template <class F>
  void for_each_cell(const Box& box, F&& visit) const;

 private:
  // Rectilinear: the interval of axis `a` holding coordinate x, found in the
  // borders (a table per voxel would cost memory in proportion to the
  // declared size, however few the intervals).
  std::uint32_t interval_of(int a, std::uint32_t x) const {
    const auto& list = borders_[a];
    return static_cast<std::uint32_t>(std::upper_bound(list.begin(), list.end(), x) - list.begin() - 1);
  }

  VolumeLayout layout_;
  std::array<std::vector<std::uint32_t>, 3> borders_;  // rectilinear
  std::vector<std::uint64_t> cells_;                   // nested: cell words
  std::uint64_t cell_edge_ = 0;
  Dims cell_grid_{};
};

template <class F>
void GridStructure::for_each_cell(const Box& box, F&& visit) const {
  const Dims& d = layout_.dims;
  switch (layout_.kind) {
    case StructureKind::Regular:
      for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
        for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
          for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x)
            visit(Box{{x, y, z}, {x + 1, y + 1, z + 1}}, (std::uint64_t{z} * d[1] + y) * d[0] + x);
      return;
    case StructureKind::Bricked: {
      const BrickGrid bricks(d, layout_.cell_log2);
      for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
        for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
          for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x)
            visit(Box{{x, y, z}, {x + 1, y + 1, z + 1}}, bricks.value_index(x, y, z));
      return;
    }
    case StructureKind::Rectilinear: {
      std::uint32_t lo[3], hi[3];
      for (int a = 0; a < 3; ++a) lo[a] = interval_of(a, box.lo[a]), hi[a] = interval_of(a, box.hi[a] - 1);
      const std::uint64_t nx = borders_[0].size() - 1, ny = borders_[1].size() - 1;
      for (std::uint32_t k = lo[2]; k <= hi[2]; ++k)
        for (std::uint32_t j = lo[1]; j <= hi[1]; ++j)
          for (std::uint32_t i = lo[0]; i <= hi[0]; ++i) {
            const std::uint32_t c[3] = {i, j, k};
            Box region;
            for (int a = 0; a < 3; ++a) {
              region.lo[a] = std::max(borders_[a][c[a]], box.lo[a]);
              region.hi[a] = std::min(borders_[a][c[a] + 1], box.hi[a]);
            }
            visit(region, (std::uint64_t{k} * ny + j) * nx + i);
          }
      return;
    }
    case StructureKind::Nested: {
      const std::uint64_t C = cell_edge_;
      std::uint64_t c0[3], c1[3];
      for (int a = 0; a < 3; ++a) c0[a] = box.lo[a] / C, c1[a] = (box.hi[a] - 1) / C;
      for (std::uint64_t ck = c0[2]; ck <= c1[2]; ++ck)
        for (std::uint64_t cj = c0[1]; cj <= c1[1]; ++cj)
          for (std::uint64_t ci = c0[0]; ci <= c1[0]; ++ci) {
            const std::uint64_t word = cells_[(ck * cell_grid_[1] + cj) * cell_grid_[0] + ci];
            const std::uint64_t first = word & ((std::uint64_t{1} << 56) - 1);
            const std::uint64_t h = C >> (word >> 56);
            const std::uint64_t cell[3] = {ci, cj, ck};
            std::uint64_t start[3], end[3], m[3], p0[3], p1[3];
            for (int a = 0; a < 3; ++a) {
              start[a] = cell[a] * C;
              end[a] = std::min<std::uint64_t>(start[a] + C, d[a]);
              m[a] = (end[a] - start[a] + h - 1) / h;
              p0[a] = (std::max<std::uint64_t>(box.lo[a], start[a]) - start[a]) / h;
              p1[a] = (std::min<std::uint64_t>(box.hi[a], end[a]) - 1 - start[a]) / h;
            }
            for (std::uint64_t r = p0[2]; r <= p1[2]; ++r)
              for (std::uint64_t q = p0[1]; q <= p1[1]; ++q)
                for (std::uint64_t p = p0[0]; p <= p1[0]; ++p) {
                  const std::uint64_t v[3] = {p, q, r};
                  Box region;
                  for (int a = 0; a < 3; ++a) {
                    region.lo[a] = static_cast<std::uint32_t>(std::max<std::uint64_t>(start[a] + v[a] * h, box.lo[a]));
                    region.hi[a] = static_cast<std::uint32_t>(
                        std::min<std::uint64_t>(std::min(start[a] + (v[a] + 1) * h, end[a]), box.hi[a]));
                  }
                  visit(region, first + (r * m[1] + q) * m[0] + p);
                }
          }
      return;
    }
    case StructureKind::Octree:
      return;
  }
}

}  // namespace ivol::detail
