#include "stored_levels.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "ivol/encoding.hpp"
#include "ivol/error.hpp"

namespace ivol::detail {

namespace {
__extension__ typedef unsigned __int128 u128;

constexpr std::uint8_t kPlusInfinity = 1, kMinusInfinity = 2, kNaN = 4;
constexpr double kBinary16Unit = 1.0 / 16777216.0;  // 2^-24: every finite binary16 value is a multiple
}  // namespace

StoredLevels::StoredLevels(const Dims& dims, unsigned brick_log2, ValueEncoding encoding, unsigned first_level)
    : dims_(dims), brick_log2_(brick_log2), encoding_(encoding) {
  const unsigned depth = depth_for(dims);
  if (first_level == 0 || first_level > depth) return;
  const bool half = encoding == ValueEncoding::Binary16;
  const bool wide = encoding == ValueEncoding::Float32;  // decoded as they come; every level inexact
  if (!wide) {
    decoded_.resize(65536);
    units_.resize(65536);
    special_.resize(65536);
  }
  for (std::uint32_t code = 0; code < decoded_.size(); ++code) {
    const double v = decode_value(encoding, code);
    decoded_[code] = v;
    if (std::isnan(v))
      special_[code] = kNaN;
    else if (std::isinf(v))
      special_[code] = v > 0 ? kPlusInfinity : kMinusInfinity;
    else
      units_[code] = static_cast<std::int64_t>(half ? v / kBinary16Unit : v);
  }
  // The largest value's units: a cell of n voxels sums at most n times it.
  const double largest_units = half ? 65504.0 / kBinary16Unit : 65535.0;
  const std::uint64_t edge = std::uint64_t{1} << brick_log2;
  for (unsigned k = first_level; k <= depth; ++k) {
    Level level;
    level.k = k;
    level.dims = lod_dims(dims, k);
    double cell_voxels = 1.0;
    for (int a = 0; a < 3; ++a)
      cell_voxels *= static_cast<double>(std::min<std::uint64_t>(std::uint64_t{1} << k, dims[a]));
    level.exact = !wide && cell_voxels * largest_units < 9007199254740992.0;  // 2^53
    const std::uint64_t plane = std::uint64_t{level.dims[0]} * level.dims[1];
    if (level.exact) {
      level.exact_sums.assign(plane, 0);
      if (half) level.specials.assign(plane, 0);
      if (finest_exact_ == SIZE_MAX) finest_exact_ = levels_.size();
    } else {
      level.sums.assign(plane, 0.0);
    }
    level.layer.resize(plane * std::min<std::uint64_t>(edge, level.dims[2]));
    levels_.push_back(std::move(level));
  }
}

std::uint64_t StoredLevels::memory_bytes() const {
  std::uint64_t bytes = decoded_.size() * (sizeof(double) + sizeof(std::int64_t) + 1);
  for (const Level& l : levels_)
    bytes += l.sums.size() * sizeof(double) + l.exact_sums.size() * 8 + l.specials.size() + l.layer.size() * 4;
  return bytes;
}

// What the sequential binary64 sum of the cell is: for an exact level, its
// exact sum (every partial sum fits 53 bits), or what its infinities and
// NaNs make of any sum.
double StoredLevels::cell_sum(const Level& level, std::size_t cell) const {
  if (!level.exact) return level.sums[cell];
  if (!level.specials.empty() && level.specials[cell] != 0) {
    const std::uint8_t s = level.specials[cell];
    if ((s & kNaN) || (s & kPlusInfinity && s & kMinusInfinity)) return std::nan("");
    return s & kPlusInfinity ? HUGE_VAL : -HUGE_VAL;
  }
  const auto units = static_cast<double>(level.exact_sums[cell]);  // below 2^53: exact
  return encoding_ == ValueEncoding::Binary16 ? units * kBinary16Unit : units;
}

void StoredLevels::finish_slice(std::size_t index, std::uint64_t z, std::vector<std::vector<Completed>>& completed) {
  Level& level = levels_[index];
  const unsigned k = level.k;
  const std::uint64_t mx = level.dims[0], my = level.dims[1];
  const std::uint64_t edge = std::uint64_t{1} << brick_log2_;
  if (level.exact)  // the next coarser exact level's cells take this slice's sums (and pass them on)
    for (std::size_t c = index + 1; c < levels_.size(); ++c) {
      Level& coarse = levels_[c];
      if (!coarse.exact) continue;
      const unsigned shift = coarse.k - k;
      for (std::uint64_t j = 0; j < my; ++j)
        for (std::uint64_t i = 0; i < mx; ++i) {
          const std::size_t to = (j >> shift) * coarse.dims[0] + (i >> shift);
          coarse.exact_sums[to] += level.exact_sums[j * mx + i];
          if (!coarse.specials.empty()) coarse.specials[to] |= level.specials[j * mx + i];
        }
      break;
    }
  const std::uint64_t cz = z + 1 - (std::uint64_t{level.slice} << k);
  std::uint32_t* out = level.layer.data() + (level.slice & (edge - 1)) * mx * my;
  for (std::uint64_t j = 0; j < my; ++j) {
    const std::uint64_t cy = std::min<std::uint64_t>((j + 1) << k, dims_[1]) - (j << k);
    for (std::uint64_t i = 0; i < mx; ++i) {
      const std::uint64_t cx = std::min<std::uint64_t>((i + 1) << k, dims_[0]) - (i << k);
      // The exact number of voxels, rounded once (spec §12.3).
      const auto voxels = static_cast<double>(static_cast<u128>(cz) * cy * cx);
      out[j * mx + i] = encode_value(encoding_, cell_sum(level, j * mx + i) / voxels);
    }
  }
  std::fill(level.sums.begin(), level.sums.end(), 0.0);
  std::fill(level.exact_sums.begin(), level.exact_sums.end(), 0);
  std::fill(level.specials.begin(), level.specials.end(), 0);
  ++level.slice;
  if ((level.slice & (edge - 1)) == 0 || level.slice == level.dims[2]) {
    const std::uint64_t slices = level.slice - ((level.slice - 1) & ~(edge - 1));
    Completed done;
    done.layer = static_cast<std::uint32_t>((level.slice - 1) >> brick_log2_);
    done.values.assign(level.layer.begin(), level.layer.begin() + static_cast<std::ptrdiff_t>(slices * mx * my));
    completed[index].push_back(std::move(done));
  }
}

namespace {

// Stored bits as the number they hold: 16-bit codes through the table of
// every code's value, float32 bits as they are (spec §9).
struct DecodeCode {
  const double* table;
  double operator()(std::uint16_t code) const { return table[code]; }
};
struct DecodeFloat32 {
  double operator()(std::uint32_t bits) const {
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
  }
};

// One row into the cells of `L` levels that are not exact, in runs of 2^k0
// voxels (k0 the finest of them), within which every level's cell is one:
// each level's sum stays in a register through the run, and the levels'
// additions, independent of one another, overlap. Each cell still takes
// its voxels one by one in order.
template <int L, class T, class Decode>
void sum_runs(const T* row, std::uint64_t width, const Decode& decoded, double* const* cells, const unsigned* shift) {
  const std::uint64_t run = std::uint64_t{1} << shift[0];
  for (std::uint64_t x0 = 0; x0 < width; x0 += run) {
    double acc[L];
    for (int l = 0; l < L; ++l) acc[l] = cells[l][x0 >> shift[l]];
    const std::uint64_t end = std::min(width, x0 + run);
    for (std::uint64_t x = x0; x < end; ++x) {
      const double v = decoded(row[x]);
      for (int l = 0; l < L; ++l) acc[l] = acc[l] + v;
    }
    for (int l = 0; l < L; ++l) cells[l][x0 >> shift[l]] = acc[l];
  }
}

}  // namespace

template <class T>
void StoredLevels::sum_row_inexact(const T* row, double* const* cells, const std::vector<std::size_t>& inexact) const {
  unsigned shift[32];
  for (std::size_t n = 0; n < inexact.size(); ++n) shift[n] = levels_[inexact[n]].k;
  const auto decoded = [&] {
    if constexpr (sizeof(T) == 2)
      return DecodeCode{decoded_.data()};
    else
      return DecodeFloat32{};
  }();
  // Levels come finest first: shift[0] is the finest.
  switch (inexact.size()) {
    case 1:
      return sum_runs<1>(row, dims_[0], decoded, cells, shift);
    case 2:
      return sum_runs<2>(row, dims_[0], decoded, cells, shift);
    case 3:
      return sum_runs<3>(row, dims_[0], decoded, cells, shift);
    case 4:
      return sum_runs<4>(row, dims_[0], decoded, cells, shift);
    case 5:
      return sum_runs<5>(row, dims_[0], decoded, cells, shift);
    case 6:
      return sum_runs<6>(row, dims_[0], decoded, cells, shift);
    case 7:
      return sum_runs<7>(row, dims_[0], decoded, cells, shift);
    case 8:
      return sum_runs<8>(row, dims_[0], decoded, cells, shift);
    default:
      for (std::uint64_t x = 0; x < dims_[0]; ++x) {
        const double v = decoded(row[x]);
        for (std::size_t n = 0; n < inexact.size(); ++n) {
          double& sum = cells[n][x >> shift[n]];
          sum = sum + v;
        }
      }
  }
}

void StoredLevels::add(const std::uint16_t* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready) {
  if (encoding_ == ValueEncoding::Float32)
    throw Error(ErrorClass::InvalidArgument, "stored levels: 16-bit values given for a float32 grid");
  add_slices(values, z0, count, ready);
}

void StoredLevels::add(const std::uint32_t* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready) {
  if (encoding_ != ValueEncoding::Float32)
    throw Error(ErrorClass::InvalidArgument, "stored levels: float32 values given for a 16-bit grid");
  add_slices(values, z0, count, ready);
}

template <class T>
void StoredLevels::add_slices(const T* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready) {
  std::vector<std::vector<Completed>> completed(levels_.size());
  // The levels summed voxel by voxel: the finest exact one and every one
  // that is not exact, each voxel decoded once for all of them (their sums
  // are independent chains of additions, which the processor overlaps).
  std::vector<std::size_t> inexact;
  for (std::size_t l = 0; l < levels_.size(); ++l)
    if (!levels_[l].exact) inexact.push_back(l);
  std::vector<double*> cells(inexact.size());
  for (std::uint32_t n = 0; n < count; ++n) {
    const std::uint64_t z = std::uint64_t{z0} + n;
    const T* slice = values + std::uint64_t{n} * dims_[1] * dims_[0];
    for (std::uint64_t y = 0; y < dims_[1]; ++y) {
      const T* row = slice + y * dims_[0];
      if (sizeof(T) == 2 && finest_exact_ != SIZE_MAX) {  // float32 levels are never exact
        Level& level = levels_[finest_exact_];
        const unsigned k = level.k;
        std::int64_t* sums = level.exact_sums.data() + (y >> k) * level.dims[0];
        // A cell's 2^k voxels of the row summed in a register, then added:
        // adding each to memory waited on the store before it.
        const std::uint64_t run = std::uint64_t{1} << k, whole = dims_[0] >> k;
        for (std::uint64_t c = 0; c < whole; ++c) {
          std::int64_t cell = 0;
          for (std::uint64_t x = c << k; x < (c + 1) << k; ++x) cell += units_[row[x]];
          sums[c] += cell;
        }
        for (std::uint64_t x = whole * run; x < dims_[0]; ++x) sums[x >> k] += units_[row[x]];
        if (!level.specials.empty()) {
          std::uint8_t* flags = level.specials.data() + (y >> k) * level.dims[0];
          for (std::uint64_t c = 0; c < whole; ++c) {
            std::uint8_t cell = 0;
            for (std::uint64_t x = c << k; x < (c + 1) << k; ++x) cell |= special_[row[x]];
            flags[c] |= cell;
          }
          for (std::uint64_t x = whole * run; x < dims_[0]; ++x) flags[x >> k] |= special_[row[x]];
        }
      }
      if (inexact.empty()) continue;
      for (std::size_t n2 = 0; n2 < inexact.size(); ++n2) {
        Level& level = levels_[inexact[n2]];
        cells[n2] = level.sums.data() + (y >> level.k) * level.dims[0];
      }
      sum_row_inexact(row, cells.data(), inexact);
    }
    // A level's slice is complete at its last full-resolution slice; the
    // finer exact levels finish first, so that the coarser have their sums.
    for (std::size_t l = 0; l < levels_.size(); ++l) {
      const unsigned k = levels_[l].k;
      if (((z + 1) & ((std::uint64_t{1} << k) - 1)) == 0 || z + 1 == dims_[2]) finish_slice(l, z, completed);
    }
  }
  for (std::size_t l = 0; l < levels_.size(); ++l)
    for (const Completed& c : completed[l]) ready(levels_[l].k, levels_[l].dims, c.layer, c.values.data());
}

}  // namespace ivol::detail
