// Writing a 4^3 cube of voxels from the values of its eight children (eight
// 2^3 octets, spec §8.3 child order, 64 stored values in a row) into a
// [z][y][x] float buffer with vector instructions: the dense path's innermost
// step (tree_walk.hpp), which a whole read of a scan takes for nearly every
// voxel. Chosen at run time: null where the CPU lacks the instructions.
// Internal to libformat.
#pragma once

#include <cstdint>

namespace ivol::detail {

// `out` is the cube's first voxel; rows nx floats apart, planes `plane`.
using CubeWriter = void (*)(const std::uint8_t* values, float* out, std::uint64_t nx, std::uint64_t plane);

// binary16 values, converted exactly (F16C), as binary16_to_float with NaNs
// quieted (as the conversion through binary64 of VolumeLayout::physical).
CubeWriter binary16_cube_writer();
// uint16 codes as floats, exactly (AVX2).
CubeWriter uint16_cube_writer();

}  // namespace ivol::detail
