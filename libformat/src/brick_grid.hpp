// The bricked regular grid's arithmetic (spec §8A.4, structure_kind 5):
// bricks of 2^b voxels per side in raster order, the voxels of each brick in
// raster order, one brick per values block. Internal to libformat.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <optional>

#include "ivol/geometry.hpp"

namespace ivol::detail {

class BrickGrid {
 public:
  BrickGrid(const Dims& dims, unsigned brick_log2) : dims_(dims), log2_(brick_log2) {
    for (int a = 0; a < 3; ++a) count_[a] = static_cast<std::uint32_t>((std::uint64_t{dims[a]} + edge() - 1) >> log2_);
  }
  std::uint64_t edge() const { return std::uint64_t{1} << log2_; }
  const Dims& bricks() const { return count_; }  // bricks along x, y, z
  std::uint64_t brick_count() const { return std::uint64_t{count_[0]} * count_[1] * count_[2]; }

  // Voxels of brick (i, j, k) along each axis: the edge, less at the far faces.
  Dims extent(std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    const std::uint32_t c[3] = {i, j, k};
    Dims e{};
    for (int a = 0; a < 3; ++a)
      e[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(edge(), dims_[a] - (std::uint64_t{c[a]} << log2_)));
    return e;
  }
  // Value index of brick (i, j, k)'s first voxel: the bricks before it in
  // raster order hold whole layers, whole rows of the layer, and whole bricks.
  std::uint64_t first_value(std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    const Dims e = extent(i, j, k);
    const std::uint64_t layer = (std::uint64_t{k} << log2_) * dims_[1] * dims_[0];
    const std::uint64_t row = (std::uint64_t{j} << log2_) * dims_[0] * e[2];
    return layer + row + (std::uint64_t{i} << log2_) * e[1] * e[2];
  }
  // The brick whose first voxel has value index `first`; false when no brick
  // starts there.
  bool brick_at(std::uint64_t first, std::array<std::uint32_t, 3>& brick) const {
    const std::uint64_t total = std::uint64_t{dims_[0]} * dims_[1] * dims_[2];
    if (first >= total) return false;
    if (first == 0) return brick = {0, 0, 0}, true;
    // Bounded by `total` (the caller keeps it at most 2^56): min(edge, size).
    const std::uint64_t layer = std::min<std::uint64_t>(edge(), dims_[2]) * dims_[1] * dims_[0];
    const auto k = static_cast<std::uint32_t>(first / layer);
    const std::uint64_t ez = extent(0, 0, k)[2];
    const std::uint64_t in_layer = first - k * layer;
    const std::uint64_t row = std::min<std::uint64_t>(edge(), dims_[1]) * dims_[0] * ez;
    const auto j = static_cast<std::uint32_t>(in_layer / row);
    const std::uint64_t ey = extent(0, j, k)[1];
    const std::uint64_t in_row = in_layer - j * row;
    const std::uint64_t one = std::min<std::uint64_t>(edge(), dims_[0]) * ey * ez;
    if (in_row % one != 0) return false;
    brick = {static_cast<std::uint32_t>(in_row / one), j, k};
    return true;
  }
  // Value index of voxel (x, y, z).
  std::uint64_t value_index(std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
    const std::uint32_t i = x >> log2_, j = y >> log2_, k = z >> log2_;
    const std::uint64_t mask = edge() - 1;
    const Dims e = extent(i, j, k);
    return first_value(i, j, k) + ((z & mask) * e[1] + (y & mask)) * e[0] + (x & mask);
  }

 private:
  Dims dims_;
  unsigned log2_;
  Dims count_{};
};

// The dims a bricked grid's block of stream 3 (the volume) or 7 (a stored
// level of detail, spec §8A.5) is a brick of; none for other blocks.
inline std::optional<Dims> bricked_stream_dims(const VolumeLayout& v, std::uint8_t stream, std::uint8_t level) {
  if (v.kind != StructureKind::Bricked) return std::nullopt;
  if (stream == 3) return v.dims;
  if (stream == 7 && level >= 1 && level <= v.depth) return lod_dims(v.dims, level);
  return std::nullopt;
}

// The brick a values block of a bricked grid holds (stream 3, or 7 for a
// stored level of detail), as codec 3 needs it; none for other blocks, or
// for a block that does not start at a brick (salvage).
inline std::optional<Dims> brick_of_block(const VolumeLayout& v, std::uint8_t stream, std::uint8_t level,
                                          std::uint64_t first) {
  const std::optional<Dims> dims = bricked_stream_dims(v, stream, level);
  if (!dims) return std::nullopt;
  const Dims& d = *dims;
  // More than 2^56 voxels is refused elsewhere (spec §8A); here it must not overflow.
  if (std::uint64_t{d[0]} * d[1] > (std::uint64_t{1} << 56) / d[2]) return std::nullopt;
  const BrickGrid grid(d, v.cell_log2);
  std::array<std::uint32_t, 3> brick{};
  if (!grid.brick_at(first, brick)) return std::nullopt;
  return grid.extent(brick[0], brick[1], brick[2]);
}

}  // namespace ivol::detail
