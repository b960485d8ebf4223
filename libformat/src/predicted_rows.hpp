// The per-voxel arithmetic of codec 3 (spec §7.2), one brick row at a time,
// shared by the encoder, the decoder and the least-squares fit so that all
// three predict every voxel exactly alike.
//
// Speed: the spec's sum S = Σ t_k·U_k needs 35 bits on u16 values. On the
// centred values C = U − 32768 (which fit an i16) S = S_c + 32768·Σt, and
// since s ≤ 15, floor((S + r) / 2^s) = floor((S_c + r) / 2^s) + Σt·2^(15−s):
// the constant moves into the level. For every realistic set of taps S_c and
// the prediction then fit 32 bits, and the row loops vectorise; taps that do
// not (any i16 taps are valid) take the same loops in 64 bits.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cpu_features.hpp"

namespace ivol::detail {

struct PredictorTaps {
  unsigned shift = 0;
  // Neighbours (x-1), (y-1), (z-1), (x-1,y-1), (x-1,z-1), (y-1,z-1), (x-1,y-1,z-1).
  std::array<std::int32_t, 7> t{};
  std::int32_t bias = 0;  // the level L, added after the shift
};
inline constexpr PredictorTaps kLorenzoTaps{0, {1, 1, 1, -1, -1, -1, 1}, 0};

// The taps in the form the row loops use (see the top of this file).
struct RowPredictor {
  explicit RowPredictor(const PredictorTaps& taps) : shift(taps.shift) {
    for (int k = 0; k < 7; ++k) t[k] = static_cast<std::int16_t>(taps.t[k]);
    round = shift ? std::int32_t{1} << (shift - 1) : 0;
    std::int64_t sum = 0, sum_abs = 0;
    for (std::int32_t tap : taps.t) sum += tap, sum_abs += std::llabs(tap);
    level = taps.bias + sum * (std::int64_t{1} << (15 - shift));
    const std::int64_t s_max = 32768 * sum_abs + round;
    const std::int64_t q_max = (s_max >> shift) + 1;
    narrow = s_max < (std::int64_t{1} << 31) && q_max + std::llabs(level) < (std::int64_t{1} << 31);
    decode_narrow =
        narrow && s_max + (std::llabs(level) << shift) + 32768 * std::int64_t{std::abs(t[0])} < (std::int64_t{1} << 31);
  }
  std::array<std::int16_t, 7> t;  // every tap is an i16 (spec §7.2), and products of i16 vectorise best
  unsigned shift;
  std::int32_t round;
  std::int64_t level;  // L + Σt·2^(15−s)
  bool narrow;         // every sum and prediction fits 32 bits
  bool decode_narrow;  // and decode_row's sums, which hold the level too
};

inline std::uint16_t zigzag16(std::uint16_t value, std::uint16_t prediction) {
  const auto s = static_cast<std::int16_t>(static_cast<std::uint16_t>(value - prediction));
  return static_cast<std::uint16_t>((static_cast<std::uint16_t>(s) << 1) ^ static_cast<std::uint16_t>(s >> 15));
}

inline std::uint16_t unzigzag16(std::uint16_t z, std::uint16_t prediction) {
  const auto d = static_cast<std::uint16_t>((z >> 1) ^ (0u - (z & 1u)));
  return static_cast<std::uint16_t>(prediction + d);
}

template <class Acc>
inline Acc centred(std::uint16_t u) {
  return static_cast<std::int16_t>(u ^ 0x8000);
}

template <class Acc>
inline Acc clamp16(Acc p) {
  return p < 0 ? 0 : p > 65535 ? 65535 : p;
}

// The four rows an interior row is predicted from: the row itself (c), the
// row before it along y (up), along z (back) and along both (up_back).
struct RowNeighbours {
  const std::uint16_t* up;
  const std::uint16_t* back;
  const std::uint16_t* up_back;
};

// Where an interior row's loops may start: at x = 0, though voxel 0 is
// predicted from the faces (its value there has no meaning and the caller
// replaces or ignores it), so that a loop runs over the whole row, a
// multiple of the vector width for the usual bricks, with no scalar
// remainder (which took a third of its time). The neighbours at x − 1 = −1
// are then the ends of earlier rows of the brick, except in the first
// interior row (y = z = 1), whose up-back row starts the brick: that row
// starts at x = 1. `brick` is the brick's first voxel.
inline std::uint32_t first_x(const std::uint16_t* brick, const RowNeighbours& n) { return n.up_back == brick ? 1 : 0; }

// Residuals z[first .. len) of an interior row (y, z > 0) whose values are
// all known (the encoder): independent voxels, one vectorisable loop;
// first = first_x(), z[0] of no meaning when it is 0.
template <class Acc>
IVOL_VECTOR_CLONES void residual_row(const RowPredictor& p, const std::uint16_t* c, const RowNeighbours& n,
                                     std::uint32_t first, std::uint32_t len, std::uint16_t* z) {
  const Acc t0 = p.t[0], t1 = p.t[1], t2 = p.t[2], t3 = p.t[3], t4 = p.t[4], t5 = p.t[5], t6 = p.t[6];
  const Acc round = p.round, level = static_cast<Acc>(p.level);
  const unsigned shift = p.shift;
  const std::uint16_t *up = n.up, *back = n.back, *ub = n.up_back;
  for (std::ptrdiff_t x = first; x < static_cast<std::ptrdiff_t>(len); ++x) {
    const Acc s = t0 * centred<Acc>(c[x - 1]) + t1 * centred<Acc>(up[x]) + t2 * centred<Acc>(back[x]) +
                  t3 * centred<Acc>(up[x - 1]) + t4 * centred<Acc>(back[x - 1]) + t5 * centred<Acc>(ub[x]) +
                  t6 * centred<Acc>(ub[x - 1]);
    const Acc q = clamp16<Acc>(((s + round) >> shift) + level);
    z[x] = zigzag16(c[x], static_cast<std::uint16_t>(q));
  }
}

// Σ (U − floor((S + r) / 2^s) − L) over an interior row, unclamped: what the
// least-squares fit's level is the mean of.
template <class Acc>
std::int64_t level_row(const RowPredictor& p, const std::uint16_t* c, const RowNeighbours& n, std::uint32_t len) {
  const Acc t0 = p.t[0], t1 = p.t[1], t2 = p.t[2], t3 = p.t[3], t4 = p.t[4], t5 = p.t[5], t6 = p.t[6];
  const Acc round = p.round, level = static_cast<Acc>(p.level);
  const unsigned shift = p.shift;
  const std::uint16_t *up = n.up, *back = n.back, *ub = n.up_back;
  std::int64_t sum = 0;
  for (std::uint32_t x = 1; x < len; ++x) {
    const Acc s = t0 * centred<Acc>(c[x - 1]) + t1 * centred<Acc>(up[x]) + t2 * centred<Acc>(back[x]) +
                  t3 * centred<Acc>(up[x - 1]) + t4 * centred<Acc>(back[x - 1]) + t5 * centred<Acc>(ub[x]) +
                  t6 * centred<Acc>(ub[x - 1]);
    sum += std::int64_t{c[x]} - (((s + round) >> shift) + level);
  }
  return sum;
}

// Decoding an interior row from its residuals z[]: what does not depend on
// the voxel before along x is summed for the whole row first (vectorised):
// the six neighbours in earlier rows, the rounding, the level times 2^s
// (floor(a / 2^s) + L = floor((a + L·2^s) / 2^s)) and t_0's share of
// centring, so that the chain from one voxel to the next is a multiply, an
// add, a shift and the residual's add. The clamp is a branch that is almost
// never taken, off that chain. Acc must hold those sums:
// RowPredictor::decode_narrow says when 32 bits do.
//
// The sums of voxels first .. len (first_x(); partial[0] and delta[0]
// unused) and their residuals' differences.
template <class Acc>
IVOL_VECTOR_CLONES void row_partials(const RowPredictor& p, const RowNeighbours& n, std::uint32_t first,
                                     std::uint32_t len, const std::uint16_t* z, Acc* partial, std::uint16_t* delta) {
  const Acc t0 = p.t[0], t1 = p.t[1], t2 = p.t[2], t3 = p.t[3], t4 = p.t[4], t5 = p.t[5], t6 = p.t[6];
  const Acc constant = p.round + static_cast<Acc>(p.level * (std::int64_t{1} << p.shift)) - 32768 * t0;
  const std::uint16_t *up = n.up, *back = n.back, *ub = n.up_back;
  for (std::ptrdiff_t x = first; x < static_cast<std::ptrdiff_t>(len); ++x) {
    partial[x] = t1 * centred<Acc>(up[x]) + t2 * centred<Acc>(back[x]) + t3 * centred<Acc>(up[x - 1]) +
                 t4 * centred<Acc>(back[x - 1]) + t5 * centred<Acc>(ub[x]) + t6 * centred<Acc>(ub[x - 1]) + constant;
    delta[x] = unzigzag16(z[x], 0);
  }
}

// One voxel of that chain: the prediction from the row's sum and the voxel
// before, clamped, plus the residual.
template <class Acc>
inline Acc next_in_row(Acc partial, Acc previous, Acc t0, unsigned shift, std::uint16_t delta) {
  Acc q = (partial + t0 * previous) >> shift;
  if (__builtin_expect(q < 0 || q > 65535, 0)) q = q < 0 ? 0 : 65535;
  return static_cast<std::uint16_t>(q + delta);
}

// Decodes c[1 .. len) of an interior row (c[0], a face voxel, known).
// `partial` and `delta` hold len values of scratch.
template <class Acc>
void decode_row(const RowPredictor& p, std::uint16_t* c, const RowNeighbours& n, std::uint32_t first, std::uint32_t len,
                const std::uint16_t* z, Acc* partial, std::uint16_t* delta) {
  row_partials<Acc>(p, n, first, len, z, partial, delta);
  const Acc t0 = p.t[0];
  Acc previous = c[0];
  for (std::uint32_t x = 1; x < len; ++x)
    c[x] = static_cast<std::uint16_t>(previous = next_in_row<Acc>(partial[x], previous, t0, p.shift, delta[x]));
}

// The same for two rows that do not depend on each other, their chains
// interleaved: a row's voxels wait on one another (a multiply, an add and a
// shift each), two rows' chains share the core's units. `partial` and
// `delta` hold 2·len values of scratch.
template <class Acc>
void decode_row_pair(const RowPredictor& p, std::uint16_t* c, const RowNeighbours& n, std::uint32_t first,
                     const std::uint16_t* z, std::uint16_t* c2, const RowNeighbours& n2, std::uint32_t first2,
                     const std::uint16_t* z2, std::uint32_t len, Acc* partial, std::uint16_t* delta) {
  Acc* const partial2 = partial + len;
  std::uint16_t* const delta2 = delta + len;
  row_partials<Acc>(p, n, first, len, z, partial, delta);
  row_partials<Acc>(p, n2, first2, len, z2, partial2, delta2);
  const Acc t0 = p.t[0];
  const unsigned shift = p.shift;
  Acc previous = c[0], previous2 = c2[0];
  for (std::uint32_t x = 1; x < len; ++x) {
    c[x] = static_cast<std::uint16_t>(previous = next_in_row<Acc>(partial[x], previous, t0, shift, delta[x]));
    c2[x] = static_cast<std::uint16_t>(previous2 = next_in_row<Acc>(partial2[x], previous2, t0, shift, delta2[x]));
  }
}

}  // namespace ivol::detail
