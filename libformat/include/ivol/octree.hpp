// The pointer-packed octree in memory, exactly as the file stores it (spec §8):
// breadth-first node words (8-bit child mask, 56-bit first inner child) and
// one value per node, leaves held by their value alone.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol {

struct MemoryUsage {
  std::uint64_t node_bytes = 0;
  std::uint64_t value_bytes = 0;
  std::uint64_t total() const { return node_bytes + value_bytes; }
};

constexpr std::uint64_t kFirstChildMask = (std::uint64_t{1} << 56) - 1;

inline std::uint8_t child_mask(std::uint64_t word) { return static_cast<std::uint8_t>(word >> 56); }
inline std::uint64_t first_inner_child(std::uint64_t word) { return word & kFirstChildMask; }
inline std::uint64_t make_node_word(std::uint8_t mask, std::uint64_t first_child) {
  return (std::uint64_t{mask} << 56) | (first_child & kFirstChildMask);
}

class Octree {
 public:
  Octree() = default;
  Octree(VolumeLayout layout, std::vector<std::uint64_t> nodes, std::vector<std::uint8_t> values);

  const VolumeLayout& layout() const { return layout_; }
  const std::vector<std::uint64_t>& nodes() const { return nodes_; }
  // Values, little-endian, encoding_width() bytes each, breadth-first.
  const std::vector<std::uint8_t>& value_bytes() const { return values_; }

  std::uint64_t node_word(std::uint64_t index) const { return nodes_[index]; }
  std::uint32_t value_bits(std::uint64_t index) const;

  // Stored bits and physical value of voxel (x, y, z) at level of detail `lod`.
  std::uint32_t voxel_bits(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod = 0) const;
  double voxel_value(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod = 0) const;
  // Physical values of a box at level of detail `lod`, [z][y][x], x fastest.
  std::vector<float> read_box(const Box& box, unsigned lod = 0) const;

  // Exact bytes held by the two arrays.
  MemoryUsage memory() const;
  std::uint64_t leaf_count() const;

  // Checks every rule of spec §8 and §10; throws Error(Malformed) naming the
  // first broken one. Used by tests and before writing.
  void validate() const;

 private:
  VolumeLayout layout_;
  std::vector<std::uint64_t> nodes_;
  std::vector<std::uint8_t> values_;
};

}  // namespace ivol
