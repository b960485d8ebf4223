// Building an octree from a dense volume (spec §8.5, §10).
#pragma once

#include <cstdint>

#include "ivol/geometry.hpp"
#include "ivol/octree.hpp"

namespace ivol {

struct BuildOptions {
  ValueEncoding encoding = ValueEncoding::Binary16;
  // physical = value_offset + value_scale * decoded. A float source holds
  // physical values: with uint16 the scale and offset quantise them. A uint16
  // source stored as uint16 holds the codes themselves: the scale and offset
  // only record what they mean (e.g. a grey-value calibration).
  double value_scale = 1.0;
  double value_offset = 0.0;
  // Optional, one byte per voxel like the source: full resolution is kept
  // where it is non-zero, and every node without such a voxel becomes one leaf
  // holding its mean (the paper's use). Null: lossless, only equal leaves merge.
  const std::uint8_t* keep_mask = nullptr;
  unsigned threads = 0;  // 0: all hardware threads
};

struct BuildResult {
  Octree octree;
  // Largest |source − stored physical value| over all voxels: the value
  // encoding's rounding, and the coarsening when a keep mask is given.
  double max_abs_error = 0.0;
  bool lossless = true;           // every voxel holds exactly its source value
  std::uint64_t kept_voxels = 0;  // voxels held by leaves of one voxel
  double seconds = 0.0;
};

// `data` is dense, [z][y][x] with x fastest.
BuildResult build_octree(const float* data, const Dims& dims, const BuildOptions& options);
BuildResult build_octree(const std::uint16_t* data, const Dims& dims, const BuildOptions& options);

}  // namespace ivol
