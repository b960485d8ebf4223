// A bricked grid's stored levels of detail (spec §8A.5), summed while the
// full-resolution values are written, bit for bit as §12.3 defines them:
// each cell's binary64 sum of its voxels' decoded values, in the order z,
// then y, then x, over the voxel count, encoded once. Internal to libformat.
//
// Where no partial sum of a cell can need more than binary64's 53 bits, that
// sequential sum is exact, so it equals the cell's exact sum in any order:
// such *exact* levels sum integers (uint16 codes; binary16 values in units
// of 2^-24, infinities and NaNs as flags), the finest of them voxel by
// voxel and each coarser one from its finished slices. That covers every
// level of uint16 grids below 2^37 voxels a cell and binary16 levels of
// cells up to 4096 voxels (k ≤ 4).
//
// The coarser binary16 levels (k ≥ 5), whose sums of values near 65504
// could round, are *watched*: a cell adds each row's run of its voxels as
// an integer, with the run's sum of magnitudes, while the cell's magnitudes
// stay below 2^53 units (then no partial sum in any order can round); from
// the run that would reach 2^53 on, it adds its voxels one by one in
// binary64, in order, from its exact sum so far. Volumes of ordinary values
// never leave the integers (adding every voxel in binary64 to each of five
// levels was a tenth of a binary16 conversion's time). float32 levels add
// every voxel in binary64, in order, all such levels in one pass.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol::detail {

class StoredLevels {
 public:
  // Levels first_level .. depth of a grid of `dims` in bricks of
  // 2^brick_log2 (none when first_level is 0 or beyond the depth).
  StoredLevels(const Dims& dims, unsigned brick_log2, ValueEncoding encoding, unsigned first_level);

  // A layer of bricks of level `level` is complete: `values` holds its
  // slices (the level's extent along z of brick layer `layer`, [z][y][x]
  // over the level's dims), stored bits zero-extended to 32 bits.
  using LayerReady =
      std::function<void(unsigned level, const Dims& level_dims, std::uint32_t layer, const std::uint32_t* values)>;

  // Adds full-resolution slices z0 .. z0 + count (the next ones), [z][y][x]
  // stored bits: 16-bit encodings as std::uint16_t, float32 as
  // std::uint32_t (InvalidArgument otherwise); calls `ready` for every brick
  // layer of a level they complete, finest level first.
  void add(const std::uint16_t* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready);
  void add(const std::uint32_t* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready);

  std::uint64_t memory_bytes() const;
  bool empty() const { return levels_.empty(); }

 private:
  struct Level {
    unsigned k = 0;
    Dims dims{};                           // the level's elements along each axis
    bool exact = false;                    // summed as integers (above)
    bool watched = false;                  // binary16, k ≥ 5: integers while no sum can round (above)
    std::vector<double> sums;              // not exact: the cells of the level slice being summed
    std::vector<std::int64_t> exact_sums;  // exact or watched: the same, in units (1, or 2^-24 for binary16)
    std::vector<std::uint8_t> specials;    // binary16: +inf 1, -inf 2, NaN 4 met in the cell
    std::vector<std::uint64_t> magnitudes;  // watched: Σ |units| of the cell so far
    std::vector<std::uint8_t> rounding;     // watched: 1 once the cell adds in binary64 (into sums)
    std::vector<std::uint32_t> layer;      // its finished slices of the current brick layer
    std::uint32_t slice = 0;               // the level slice being summed
  };
  struct Completed {
    std::uint32_t layer = 0;
    std::vector<std::uint32_t> values;
  };
  // Level slice `level.slice` is summed (z its last full-resolution slice):
  // its means into the level's layer, which moves out when complete; an
  // exact level's sums go into the coarser exact levels' first.
  void finish_slice(std::size_t index, std::uint64_t z, std::vector<std::vector<Completed>>& completed);
  double cell_sum(const Level& level, std::size_t cell) const;
  template <class T>
  void add_slices(const T* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready);
  // One full-resolution row into the cells of the levels that are not exact.
  template <class T>
  void sum_row_inexact(const T* row, double* const* cells, const std::vector<std::size_t>& inexact) const;
  // One row of 16-bit codes into the finest exact level and the watched ones.
  void sum_row_exact(const std::uint16_t* row, std::uint64_t y);

  Dims dims_;
  unsigned brick_log2_;
  ValueEncoding encoding_;
  std::vector<double> decoded_;          // 16-bit encodings: every code's decoded value (spec §9)
  std::vector<Level> levels_;            // finest first
  // A row's runs of 2^k voxels (k the finest watched or exact level's):
  // their sums and magnitudes in units and their special flags.
  std::vector<std::int64_t> run_sums_;
  std::vector<std::uint64_t> run_magnitudes_;
  std::vector<std::uint8_t> run_specials_;
};

}  // namespace ivol::detail
