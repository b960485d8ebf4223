// Walking the full-resolution rows a brick covers. Internal to libformat.
#pragma once

#include <algorithm>
#include <cstdint>

#include "ivol/structures.hpp"

namespace ivol::detail {

// Calls visit(value index, x0, x1, y, z) for every row segment [x0, x1) of
// full-resolution voxels at (y, z), z in [z_lo, z_hi), that one voxel of the
// brick covers.
template <class F>
void for_each_brick_row(const Brick& b, const Dims& dims, std::uint64_t z_lo, std::uint64_t z_hi, F&& visit) {
  for (std::uint32_t k = 0; k < b.count[2]; ++k) {
    const std::uint64_t z0 = b.origin[2] + std::uint64_t{k} * b.voxel[2];
    const std::uint64_t z1 = std::min<std::uint64_t>(dims[2], z0 + b.voxel[2]);
    if (z1 <= z_lo || z0 >= z_hi) continue;
    for (std::uint32_t j = 0; j < b.count[1]; ++j) {
      const std::uint64_t y0 = b.origin[1] + std::uint64_t{j} * b.voxel[1];
      const std::uint64_t y1 = std::min<std::uint64_t>(dims[1], y0 + b.voxel[1]);
      for (std::uint32_t i = 0; i < b.count[0]; ++i) {
        const std::uint64_t x0 = b.origin[0] + std::uint64_t{i} * b.voxel[0];
        const std::uint64_t x1 = std::min<std::uint64_t>(dims[0], x0 + b.voxel[0]);
        const std::uint64_t v = b.first_value + (std::uint64_t{k} * b.count[1] + j) * b.count[0] + i;
        for (std::uint64_t z = std::max(z0, z_lo); z < std::min(z1, z_hi); ++z)
          for (std::uint64_t y = y0; y < y1; ++y) visit(v, x0, x1, y, z);
      }
    }
  }
}

}  // namespace ivol::detail
