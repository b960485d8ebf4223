// A structure's bricks as it holds them: 16 bytes a brick where the Brick
// record takes 48, since an octree of a 1152³ scan has tens of millions of
// bricks and at 2048³ their records alone passed a 2 GiB cap (issue 23).
//
// A record is two 64-bit words: the origin, 21 bits an axis (x low), and
// the first value's index (40 bits, low) with a 24-bit shape code above it.
// Most bricks are cubes clipped to the volume, a power-of-two side either
// of fine voxels or as one coarse voxel (every octree and nested-grid
// brick, the regular grid's one brick): codes 0-63 name those as
// side_log2 * 2 + fine, the extent along each axis being min(side, dims -
// origin). Any other shape (the rectilinear grid's runs) is an entry of a
// table of voxel edges and counts, code 64 + entry.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <map>
#include <optional>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol {

struct Brick {
  std::array<std::uint32_t, 3> origin{};  // full-resolution voxel of the brick's first corner
  std::array<std::uint32_t, 3> voxel{};   // edge of one voxel along x, y, z, in full-resolution voxels
  std::array<std::uint32_t, 3> count{};   // voxels along x, y, z
  std::uint64_t first_value = 0;          // index of the brick's first value
  std::uint64_t voxel_count() const { return std::uint64_t{count[0]} * count[1] * count[2]; }
};

struct PackedBrick {
  std::uint64_t origin = 0;  // x | y << 21 | z << 42
  std::uint64_t value = 0;   // first value | shape code << 40
  std::uint32_t z() const { return static_cast<std::uint32_t>(origin >> 42); }
};
static_assert(sizeof(PackedBrick) == 16, "a brick record is 16 bytes");

class BrickList {
 public:
  static constexpr unsigned kAxisBits = 21;        // volumes up to 2,097,152 voxels along an axis
  static constexpr unsigned kFirstValueBits = 40;  // up to 2^40 values (10,000³ is 10^12)
  static constexpr std::uint32_t kCubeCodes = 64;

  BrickList() = default;
  // Throws Error(LimitExceeded) when an axis is longer than 2^21 voxels.
  explicit BrickList(const Dims& dims);

  // The record of a clipped cube (see above), or none if `b` is not one:
  // usable from several threads, as it needs no table.
  std::optional<PackedBrick> cube_record(const Brick& b) const;
  // Appends any brick: as a cube when it is one, else through the table.
  void push_back(const Brick& b);
  void append(const std::vector<PackedBrick>& records);
  void reserve(std::size_t n) { records_.reserve(n); }
  // The bricks by their first slice, stable (Morton order within one, as
  // generated), through 4-byte indices: 4 bytes a brick beside the records.
  void sort_by_first_slice();
  // Numbers the values brick after brick; returns how many there are.
  // Throws Error(LimitExceeded) past 2^40 values.
  std::uint64_t assign_first_values();

  std::size_t size() const { return records_.size(); }
  bool empty() const { return records_.empty(); }
  Brick operator[](std::size_t n) const { return decode(records_[n]); }
  // What the bricks hold: the records and the shape table.
  std::uint64_t memory_bytes() const;

  class const_iterator {
   public:
    using iterator_category = std::input_iterator_tag;
    using value_type = Brick;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = Brick;
    const_iterator(const BrickList* list, std::size_t n) : list_(list), n_(n) {}
    Brick operator*() const { return (*list_)[n_]; }
    const_iterator& operator++() { return ++n_, *this; }
    const_iterator operator++(int) {
      const_iterator was = *this;
      return ++n_, was;
    }
    bool operator==(const const_iterator& o) const { return n_ == o.n_; }
    bool operator!=(const const_iterator& o) const { return n_ != o.n_; }

   private:
    const BrickList* list_;
    std::size_t n_;
  };
  const_iterator begin() const { return {this, 0}; }
  const_iterator end() const { return {this, records_.size()}; }

 private:
  struct Shape {
    std::array<std::uint32_t, 3> voxel{}, count{};
  };
  Brick decode(const PackedBrick& r) const;
  static std::uint64_t pack_origin(const std::array<std::uint32_t, 3>& origin);
  std::uint32_t shape_code(const Brick& b);

  Dims dims_{};
  std::vector<PackedBrick> records_;
  std::vector<Shape> shapes_;
  std::map<std::array<std::uint32_t, 6>, std::uint32_t> shape_codes_;  // voxel and count -> code
};

}  // namespace ivol
