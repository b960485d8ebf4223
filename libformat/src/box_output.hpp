// The sink of an octree walk (tree_walk.hpp) that writes what it reports
// into a [z][y][x] buffer over the requested box, converting stored bits
// with `convert` (to physical floats, or as they are).
#pragma once

#include <cstdint>
#include <type_traits>

#include "cube_writers.hpp"
#include "ivol/geometry.hpp"
#include "tree_walk.hpp"

namespace ivol::detail {

template <class T, class Convert>
class BoxOutput {
 public:
  BoxOutput(T* out, const Box& box, Convert convert, CubeWriter cube = nullptr)
      : out_(out), box_(box), nx_(box.hi[0] - box.lo[0]), ny_(box.hi[1] - box.lo[1]), convert_(convert), cube_(cube) {}

  // A leaf, or the part of it inside the box: one value over `region`.
  void operator()(const Box& region, std::uint32_t bits) const { fill_region(out_, box_, region, convert_(bits)); }

  // The 2x2x2 voxels of one node at (x, y, z), wholly inside the box; bits(c)
  // for child c = dx | dy << 1 | dz << 2 (spec §8.3).
  template <class Bits>
  void octet(std::uint32_t x, std::uint32_t y, std::uint32_t z, Bits bits) const {
    T* p = out_ + ((std::uint64_t{z - box_.lo[2]} * ny_ + (y - box_.lo[1])) * nx_ + (x - box_.lo[0]));
    const std::uint64_t plane = nx_ * ny_;
    p[0] = convert_(bits(0));
    p[1] = convert_(bits(1));
    p[nx_] = convert_(bits(2));
    p[nx_ + 1] = convert_(bits(3));
    p[plane] = convert_(bits(4));
    p[plane + 1] = convert_(bits(5));
    p[plane + nx_] = convert_(bits(6));
    p[plane + nx_ + 1] = convert_(bits(7));
  }

  // The 4^3 voxels of a node two levels above the target at (x, y, z),
  // wholly inside the box, from its eight children's 64 stored values in a
  // row: false where this output has no vector writer (cube_writers.hpp),
  // which must convert as `convert` does.
  bool cube(std::uint32_t x, std::uint32_t y, std::uint32_t z, const std::uint8_t* values) const {
    if constexpr (std::is_same_v<T, float>) {
      if (!cube_) return false;
      cube_(values, out_ + ((std::uint64_t{z - box_.lo[2]} * ny_ + (y - box_.lo[1])) * nx_ + (x - box_.lo[0])), nx_,
            nx_ * ny_);
      return true;
    } else {
      return false;
    }
  }

 private:
  T* out_;
  Box box_;
  std::uint64_t nx_, ny_;
  Convert convert_;
  CubeWriter cube_;
};

template <class T, class Convert>
BoxOutput<T, Convert> box_output(T* out, const Box& box, Convert convert, CubeWriter cube = nullptr) {
  return BoxOutput<T, Convert>(out, box, convert, cube);
}

}  // namespace ivol::detail
