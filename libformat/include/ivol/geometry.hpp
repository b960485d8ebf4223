// Volume sizes, boxes and the octree's level arithmetic (spec §6.2, §8.1).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "ivol/encoding.hpp"

namespace ivol {

using Dims = std::array<std::uint32_t, 3>;  // voxels along x, y, z

enum class Axis { X = 0, Y = 1, Z = 2 };

// The structures a file can hold (spec §6.1: structure_kind), with their codes.
// Bricked: a regular grid stored brick by brick (spec §8A.4, format 1.3).
enum class StructureKind : std::uint8_t { Octree = 1, Regular = 2, Rectilinear = 3, Nested = 4, Bricked = 5 };

// A half-open box of voxels [lo, hi) in the coordinates of one level of detail.
struct Box {
  std::array<std::uint32_t, 3> lo{0, 0, 0};
  std::array<std::uint32_t, 3> hi{0, 0, 0};
  // Throws Error(LimitExceeded) past 2^64 - 1, as voxel_count(Dims) does.
  std::uint64_t voxel_count() const;
  bool empty() const;
  std::string to_string() const;
};

// Smallest D with 2^D >= the largest dimension.
unsigned depth_for(const Dims& dims);
// The voxels of `dims`. A valid file may have 2^31 voxels a side, 2^93 in
// all: a count past 2^64 - 1 throws Error(LimitExceeded) naming the dims
// rather than wrapping (a wrapped count sized buffers and reports).
std::uint64_t voxel_count(const Dims& dims);
// The same as a double, for reports of any size (exact up to 2^53, and for
// powers of two).
double voxel_count_approx(const Dims& dims);
// Dimensions of level of detail `lod` (ceil(size / 2^lod) per axis).
Dims lod_dims(const Dims& dims, unsigned lod);
// The box covering the whole volume at level of detail `lod`.
Box full_box(const Dims& dims, unsigned lod = 0);
// One slice, perpendicular to `axis`, at full resolution.
Box slice_box(const Dims& dims, Axis axis, std::uint32_t index);

// Everything needed to decode the arrays: what the index's fixed part and level
// table say (§6.1, §6.2), with the derived ranges.
struct VolumeLayout {
  StructureKind kind = StructureKind::Octree;
  std::uint8_t cell_log2 = 0;  // nested grid: log2 of the cell edge (spec §8A.3); bricked: of the brick edge (§8A.4)
  Dims dims{1, 1, 1};
  unsigned depth = 0;
  ValueEncoding encoding = ValueEncoding::Binary16;
  double value_scale = 1.0;
  double value_offset = 0.0;
  std::vector<std::uint64_t> inner_count;  // depth + 1 entries

  std::uint64_t total_inner() const;
  std::uint64_t total_values() const { return 1 + 8 * total_inner(); }
  std::uint64_t first_inner(unsigned level) const;
  std::uint64_t first_value(unsigned level) const;
  std::uint64_t level_values(unsigned level) const;
  // Non-padding voxels covered by node (i, j, k) of `level` (§8.1). Inline:
  // the builders ask it of every node and voxel.
  std::uint64_t weight(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    const std::uint64_t side = std::uint64_t{1} << (depth - level);
    auto overlap = [side](std::uint64_t a, std::uint64_t n) -> std::uint64_t {
      const std::uint64_t lo = a * side;
      const std::uint64_t hi = n < lo + side ? n : lo + side;
      return hi > lo ? hi - lo : 0;
    };
    return overlap(i, dims[0]) * overlap(j, dims[1]) * overlap(k, dims[2]);
  }
  // The same as a binary64 product, as spec §10 evaluates it (exact below 2^53).
  double weight_f64(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const;
  // With scale 1 and offset 0 the decoded number itself: 0 + 1 × −0 would be
  // +0, and spec §9 has readers pass a leaf's bits (−0 included) through.
  double physical(double decoded) const {
    return value_scale == 1.0 && value_offset == 0.0 ? decoded : value_offset + value_scale * decoded;
  }
};

}  // namespace ivol
