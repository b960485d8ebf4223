#include "stored_levels.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "ivol/encoding.hpp"
#include "ivol/error.hpp"
#include "stored_levels_avx2.hpp"

namespace ivol::detail {

namespace {
__extension__ typedef unsigned __int128 u128;

constexpr std::uint8_t kPlusInfinity = 1, kMinusInfinity = 2, kNaN = 4;
constexpr double kBinary16Unit = 1.0 / 16777216.0;  // 2^-24: every finite binary16 value is a multiple
constexpr double kExactLimit = 9007199254740992.0;  // 2^53: integers below it are binary64 values
constexpr std::uint64_t kExactUnits = std::uint64_t{1} << 53;
constexpr std::uint64_t kMagnitudeCap = std::uint64_t{1} << 62;
}  // namespace

StoredLevels::StoredLevels(const Dims& dims, unsigned brick_log2, ValueEncoding encoding, unsigned first_level)
    : dims_(dims), brick_log2_(brick_log2), encoding_(encoding) {
  const unsigned depth = depth_for(dims);
  if (first_level == 0 || first_level > depth) return;
  const bool half = encoding == ValueEncoding::Binary16;
  const bool wide = encoding == ValueEncoding::Float32;  // decoded as they come; every level inexact
  if (!wide) decoded_.resize(65536);
  for (std::uint32_t code = 0; code < decoded_.size(); ++code) decoded_[code] = decode_value(encoding, code);
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
    level.exact = !wide && cell_voxels * largest_units < kExactLimit;
    level.watched = half && !level.exact;
    const std::uint64_t plane = std::uint64_t{level.dims[0]} * level.dims[1];
    if (level.exact || level.watched) {
      level.exact_sums.assign(plane, 0);
      if (half) level.specials.assign(plane, 0);
    }
    if (level.watched) {
      level.magnitudes.assign(plane, 0);
      level.rounding.assign(plane, 0);
    }
    if (!level.exact) level.sums.assign(plane, 0.0);
    level.layer.resize(plane * std::min<std::uint64_t>(edge, level.dims[2]));
    levels_.push_back(std::move(level));
  }
}

std::uint64_t StoredLevels::memory_bytes() const {
  std::uint64_t bytes = decoded_.size() * sizeof(double);
  for (const Level& l : levels_)
    bytes += l.sums.size() * sizeof(double) + l.exact_sums.size() * 8 + l.specials.size() + l.layer.size() * 4 +
             l.magnitudes.size() * 8 + l.rounding.size();
  const std::uint64_t runs = levels_.empty() ? 0 : (dims_[0] >> levels_[0].k) + 1;
  return bytes + runs * (8 + 8 + 1);
}

// What the sequential binary64 sum of the cell is: for an exact level, its
// exact sum (every partial sum fits 53 bits), or what its infinities and
// NaNs make of any sum.
double StoredLevels::cell_sum(const Level& level, std::size_t cell) const {
  if (!level.exact && !level.watched) return level.sums[cell];
  if (!level.specials.empty() && level.specials[cell] != 0) {
    const std::uint8_t s = level.specials[cell];
    if ((s & kNaN) || (s & kPlusInfinity && s & kMinusInfinity)) return std::nan("");
    return s & kPlusInfinity ? HUGE_VAL : -HUGE_VAL;
  }
  // A watched cell that rounds holds its binary64 sum in units: scaling by
  // 2^-24 is exact, so it is the sum of the values.
  if (level.watched && level.rounding[cell]) return level.sums[cell] * kBinary16Unit;
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
  std::fill(level.magnitudes.begin(), level.magnitudes.end(), 0);
  std::fill(level.rounding.begin(), level.rounding.end(), 0);
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

namespace {

// A code's value in units, computed from two tables of its top six bits
// (sign and exponent), not looked up in one of 65536: that table (512 KiB)
// stayed out of the first-level cache, and its loads were most of the
// levels' time in a binary16 conversion.
struct UInt16Units {
  static std::int64_t units(std::uint16_t code) { return code; }
  static std::uint64_t magnitude(std::uint16_t code) { return code; }
  static bool special(std::uint16_t) { return false; }
  static std::uint8_t flags(std::uint16_t) { return 0; }
};
struct Binary16Units {
  // value · 2^24 = significand · scale + lead: for exponent e ≥ 1 the
  // significand's bits m shifted by e − 1 plus the leading one's 2^(e+9),
  // for e = 0 (subnormals) m itself; 0 for infinities and NaNs (e = 31),
  // which their flags stand for. Indexed by the code's top six bits.
  struct Tables {
    std::int64_t scale[64], lead[64];
    Tables() {
      for (unsigned t = 0; t < 64; ++t) {
        const unsigned e = t & 31;
        const std::int64_t sign = t & 32 ? -1 : 1;
        scale[t] = e == 31 ? 0 : sign * (std::int64_t{1} << (e == 0 ? 0 : e - 1));
        lead[t] = e == 0 || e == 31 ? 0 : sign * (std::int64_t{1} << (e + 9));
      }
    }
  };
  static const Tables& tables() {
    static const Tables t;
    return t;
  }
  static std::int64_t units(std::uint16_t h) {
    const Tables& t = tables();
    return std::int64_t{h & 1023} * t.scale[h >> 10] + t.lead[h >> 10];
  }
  static std::uint64_t magnitude(std::uint16_t h) {
    const Tables& t = tables();
    const unsigned positive = (h >> 10) & 31;  // the same code with its sign bit clear
    return static_cast<std::uint64_t>(std::int64_t{h & 1023} * t.scale[positive] + t.lead[positive]);
  }
  static bool special(std::uint16_t h) { return (h & 0x7C00) == 0x7C00; }
  static std::uint8_t flags(std::uint16_t h) {
    if (!special(h)) return 0;
    return (h & 0x3FF) ? kNaN : (h & 0x8000) ? kMinusInfinity : kPlusInfinity;
  }
};

#if defined(__SSE2__)
// Eight binary16 codes at p into the sums of their values and of their
// magnitudes. Normal numbers as binary64 lanes in units of 2^-136 (a
// code's bits << 13 are a binary32 of its value · 2^-112); subnormals
// (exponent 0, whose units are their significand) as 32-bit integer lanes,
// so that no subnormal binary32 is made and the sums do not depend on a
// processor that flushes them (MXCSR's DAZ); infinities and NaNs as 0 and
// marked in `special`. Within a run of at most 2^12 voxels every sum needs
// at most 52 bits: exact in any order.
struct EightBinary16Sums {
  __m128d sum = _mm_setzero_pd(), magnitude = _mm_setzero_pd();
  __m128i subnormal_sum = _mm_setzero_si128(), subnormal_magnitude = _mm_setzero_si128();
  __m128i special = _mm_setzero_si128();
};

inline void add_eight_binary16(const std::uint16_t* p, EightBinary16Sums& s) {
  const __m128i h = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
  const __m128i abs_mask = _mm_set1_epi32(0x7FFF), finite_max = _mm_set1_epi32(0x7BFF),
                normal_min = _mm_set1_epi32(0x0400);
  const __m128d abs_pd = _mm_castsi128_pd(_mm_set1_epi64x(0x7FFFFFFFFFFFFFFF));
  for (const __m128i v : {_mm_unpacklo_epi16(h, _mm_setzero_si128()), _mm_unpackhi_epi16(h, _mm_setzero_si128())}) {
    const __m128i bits = _mm_and_si128(v, abs_mask);
    const __m128i infinite_or_nan = _mm_cmpgt_epi32(bits, finite_max);
    const __m128i subnormal = _mm_cmplt_epi32(bits, normal_min);  // and zeros
    s.special = _mm_or_si128(s.special, infinite_or_nan);
    const __m128i sign = _mm_slli_epi32(_mm_andnot_si128(abs_mask, v), 16);
    const __m128i normal_bits = _mm_andnot_si128(_mm_or_si128(infinite_or_nan, subnormal), bits);
    const __m128 value = _mm_castsi128_ps(_mm_or_si128(_mm_slli_epi32(normal_bits, 13), sign));
    const __m128d low = _mm_cvtps_pd(value), high = _mm_cvtps_pd(_mm_movehl_ps(value, value));
    s.sum = _mm_add_pd(s.sum, _mm_add_pd(low, high));
    s.magnitude = _mm_add_pd(s.magnitude, _mm_add_pd(_mm_and_pd(low, abs_pd), _mm_and_pd(high, abs_pd)));
    const __m128i units = _mm_and_si128(subnormal, bits);  // a subnormal's units: its significand
    const __m128i negative = _mm_srai_epi32(sign, 31);
    s.subnormal_sum = _mm_add_epi32(s.subnormal_sum, _mm_sub_epi32(_mm_xor_si128(units, negative), negative));
    s.subnormal_magnitude = _mm_add_epi32(s.subnormal_magnitude, units);
  }
}

inline std::int64_t lanes_sum(__m128i v) {
  alignas(16) std::int32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), v);
  return std::int64_t{lanes[0]} + lanes[1] + lanes[2] + lanes[3];
}

inline double lanes_sum(__m128d v) { return _mm_cvtsd_f64(_mm_add_sd(v, _mm_unpackhi_pd(v, v))); }
#endif

// A row's runs of 2^k voxels of 16-bit codes: each run's sum of units,
// and, where asked, its sum of magnitudes and its special flags.
template <class Units, bool Magnitudes>
void sum_runs_exact(const std::uint16_t* row, std::uint64_t width, unsigned k, std::int64_t* sums,
                    std::uint64_t* magnitudes, std::uint8_t* specials) {
  const std::uint64_t run = std::uint64_t{1} << k;
  std::uint64_t done = 0;
  if constexpr (std::is_same_v<Units, Binary16Units>) {
    done = binary16_runs_avx2(row, width >> k, k, sums, Magnitudes ? magnitudes : nullptr, specials);
    for (std::uint64_t c = 0; c < done; ++c)
      if (specials[c]) {  // rare: the run's flags voxel by voxel
        std::uint8_t flags = 0;
        for (std::uint64_t x = c * run; x < (c + 1) * run; ++x) flags |= Units::flags(row[x]);
        specials[c] = flags;
      }
  }
  for (std::uint64_t x0 = done * run, c = done; x0 < width; x0 += run, ++c) {
    const std::uint64_t end = std::min(width, x0 + run);
    std::int64_t sum = 0;
    std::uint64_t magnitude = 0;
    std::uint8_t flags = 0;
    bool special = false;
    std::uint64_t x = x0;
#if defined(__SSE2__)
    if constexpr (std::is_same_v<Units, Binary16Units>) {
      if (end - x0 >= 8) {
        EightBinary16Sums eight;
        for (; x + 8 <= end; x += 8) add_eight_binary16(row + x, eight);
        constexpr double kUnitsPerLaneUnit = 0x1p136;  // 2^136 lane units are one of 2^-24
        sum = static_cast<std::int64_t>(lanes_sum(eight.sum) * kUnitsPerLaneUnit) + lanes_sum(eight.subnormal_sum);
        magnitude = static_cast<std::uint64_t>(lanes_sum(eight.magnitude) * kUnitsPerLaneUnit) +
                    static_cast<std::uint64_t>(lanes_sum(eight.subnormal_magnitude));
        special = _mm_movemask_epi8(eight.special) != 0;
      }
    }
#endif
    for (; x < end; ++x) {
      sum += Units::units(row[x]);
      if constexpr (Magnitudes) magnitude += Units::magnitude(row[x]);
      special = special | Units::special(row[x]);
    }
    if (special)  // rare: the run's flags voxel by voxel
      for (std::uint64_t x = x0; x < end; ++x) flags |= Units::flags(row[x]);
    sums[c] = sum;
    if constexpr (Magnitudes) magnitudes[c] = magnitude;
    specials[c] = flags;
  }
}

}  // namespace

void StoredLevels::sum_row_exact(const std::uint16_t* row, std::uint64_t y) {
  if (levels_.empty() || (!levels_[0].exact && !levels_[0].watched)) return;
  // Runs of at most 2^12 voxels: a run's magnitude stays below 2^52 units
  // (an exact level's k is at most 4, so its cells are whole runs).
  const unsigned k0 = std::min(levels_[0].k, 12u);
  const std::uint64_t width = dims_[0], runs = ((width - 1) >> k0) + 1;
  bool watched = false;
  for (const Level& l : levels_) watched = watched || l.watched;
  const bool half = encoding_ == ValueEncoding::Binary16;
  run_sums_.resize(runs);
  run_magnitudes_.resize(runs);
  run_specials_.assign(runs, 0);
  if (watched)
    sum_runs_exact<Binary16Units, true>(row, width, k0, run_sums_.data(), run_magnitudes_.data(), run_specials_.data());
  else if (half)
    sum_runs_exact<Binary16Units, false>(row, width, k0, run_sums_.data(), nullptr, run_specials_.data());
  else
    sum_runs_exact<UInt16Units, false>(row, width, k0, run_sums_.data(), nullptr, run_specials_.data());
  if (levels_[0].exact) {
    Level& level = levels_[0];
    std::int64_t* sums = level.exact_sums.data() + (y >> k0) * level.dims[0];
    for (std::uint64_t c = 0; c < runs; ++c) sums[c] += run_sums_[c];
    if (!level.specials.empty()) {
      std::uint8_t* flags = level.specials.data() + (y >> k0) * level.dims[0];
      for (std::uint64_t c = 0; c < runs; ++c) flags[c] |= run_specials_[c];
    }
  }
  // Each watched level's runs from the finer ones before it, in place:
  // run i of level k sums runs i·2^s .. (i + 1)·2^s − 1 of the last (s the
  // levels' difference), modulo 2^64 and with magnitudes saturated, both
  // used only below 2^53.
  unsigned granularity = k0;
  std::uint64_t count = runs;
  for (Level& level : levels_) {
    if (!level.watched) continue;
    const unsigned shift = level.k - granularity;
    const std::uint64_t cells = level.dims[0];
    for (std::uint64_t i = 0; i < cells; ++i) {
      std::uint64_t sum = 0, magnitude = 0;
      std::uint8_t flags = 0;
      for (std::uint64_t c = i << shift; c < std::min(count, (i + 1) << shift); ++c) {
        sum += static_cast<std::uint64_t>(run_sums_[c]);
        magnitude = std::min(magnitude + run_magnitudes_[c], kMagnitudeCap);
        flags |= run_specials_[c];
      }
      run_sums_[i] = static_cast<std::int64_t>(sum), run_magnitudes_[i] = magnitude, run_specials_[i] = flags;
    }
    granularity = level.k, count = cells;
    const std::uint64_t first_cell = (y >> level.k) * level.dims[0];
    for (std::uint64_t i = 0; i < cells; ++i) {
      const std::uint64_t cell = first_cell + i;
      level.specials[cell] |= run_specials_[i];
      if (!level.rounding[cell]) {
        // No partial sum of the cell so far or with this run can reach 2^53
        // units: the integers are the binary64 sums.
        if (level.magnitudes[cell] + run_magnitudes_[i] < kExactUnits) {
          level.exact_sums[cell] += run_sums_[i];
          level.magnitudes[cell] += run_magnitudes_[i];
          continue;
        }
        level.rounding[cell] = 1;
        level.sums[cell] = static_cast<double>(level.exact_sums[cell]);  // below 2^53: exact
      }
      double acc = level.sums[cell];
      for (std::uint64_t x = i << level.k; x < std::min(width, (i + 1) << level.k); ++x)
        acc = acc + static_cast<double>(Binary16Units::units(row[x]));
      level.sums[cell] = acc;
    }
  }
}

template <class T>
void StoredLevels::add_slices(const T* values, std::uint32_t z0, std::uint32_t count, const LayerReady& ready) {
  std::vector<std::vector<Completed>> completed(levels_.size());
  // The levels summed voxel by voxel that are neither exact nor watched
  // (float32's), each voxel decoded once for all of them (their sums are
  // independent chains of additions, which the processor overlaps).
  std::vector<std::size_t> inexact;
  for (std::size_t l = 0; l < levels_.size(); ++l)
    if (!levels_[l].exact && !levels_[l].watched) inexact.push_back(l);
  std::vector<double*> cells(inexact.size());
  for (std::uint32_t n = 0; n < count; ++n) {
    const std::uint64_t z = std::uint64_t{z0} + n;
    const T* slice = values + std::uint64_t{n} * dims_[1] * dims_[0];
    for (std::uint64_t y = 0; y < dims_[1]; ++y) {
      const T* row = slice + y * dims_[0];
      if constexpr (sizeof(T) == 2) sum_row_exact(row, y);
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
