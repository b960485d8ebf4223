// Least-squares taps for codec 3 (spec §7.2). Both fits come from one pass
// over the brick (BrickMoments): the sums are exact integers, so they are the
// same whatever the order of summation, and so are the taps.
#include "predicted_fit.hpp"

#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "cpu_features.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

namespace ivol::detail {
namespace {

// Least-squares taps are stored in units of 2^-12: fine enough that rounding
// them costs nothing measurable, coarse enough for taps up to ±8 in an i16.
constexpr unsigned kLeastSquaresShift = 12;

// Solves the k x k system a x = b (row-major a) by elimination with partial
// pivoting; false when it is singular.
bool solve(double* a, double* b, int k) {
  for (int c = 0; c < k; ++c) {
    int pivot = c;
    for (int r = c + 1; r < k; ++r)
      if (std::fabs(a[r * k + c]) > std::fabs(a[pivot * k + c])) pivot = r;
    if (!(std::fabs(a[pivot * k + c]) > 1e-9)) return false;
    if (pivot != c) {
      for (int j = 0; j < k; ++j) std::swap(a[c * k + j], a[pivot * k + j]);
      std::swap(b[c], b[pivot]);
    }
    for (int r = c + 1; r < k; ++r) {
      const double f = a[r * k + c] / a[c * k + c];
      for (int j = c; j < k; ++j) a[r * k + j] -= f * a[c * k + j];
      b[r] -= f * b[c];
    }
  }
  for (int c = k - 1; c >= 0; --c) {
    double s = b[c];
    for (int j = c + 1; j < k; ++j) s -= a[c * k + j] * b[j];
    b[c] = s / a[c * k + c];
  }
  return true;
}

// Interior rows (y, z > 0) the sample takes, times their interior voxels.
std::uint64_t sampled_voxels(const BrickDims& d, RowSample sample) {
  if (d[0] < 2 || d[1] < 2 || d[2] < 2) return 0;
  const std::uint64_t rows =
      sample.all() ? std::uint64_t{d[1] - 1} * (d[2] - 1) : std::uint64_t{d[1] / 2} * (d[2] / 2);  // odd y and odd z
  return rows * (d[0] - 1);
}

// Two rows' product and their products at a lag of one voxel:
// lag_ab = Σ_{x ≥ 1} a(x)·b(x − 1), lag_ba = Σ_{x ≥ 1} a(x − 1)·b(x);
// and Σ a. Integers below 2^53 as doubles, so exact in any order: the AVX2
// path's sums are the scalar path's.
struct RowPair {
  std::int64_t full = 0, lag_ab = 0, lag_ba = 0, sum_a = 0;
};

RowPair pair_scalar(const double* a, const double* b, std::uint32_t len) {
  double full = 0, lag_ab = 0, lag_ba = 0, sum_a = 0;
  for (std::uint32_t x = 0; x < len; ++x) {
    full += a[x] * b[x], sum_a += a[x];
    if (x > 0) lag_ab += a[x] * b[x - 1], lag_ba += a[x - 1] * b[x];
  }
  return {static_cast<std::int64_t>(full), static_cast<std::int64_t>(lag_ab), static_cast<std::int64_t>(lag_ba),
          static_cast<std::int64_t>(sum_a)};
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// All four sums in one pass, four voxels a step, the lags from loads one
// voxel on: a step reads a(x + 4) and b(x + 4), so each row is followed by
// at least one readable value (whose products the last whole step took
// for x = len − 1 and are taken back). As many separate sums, a call each,
// were a tenth of a binary16 conversion's time.
__attribute__((target("avx2"))) RowPair pair_avx2(const double* a, const double* b, std::uint32_t len) {
  __m256d full = _mm256_setzero_pd(), ab = _mm256_setzero_pd(), ba = _mm256_setzero_pd(), sa = _mm256_setzero_pd();
  std::uint32_t x = 0;
  for (; x + 4 <= len; x += 4) {
    const __m256d va = _mm256_loadu_pd(a + x), vb = _mm256_loadu_pd(b + x);
    full = _mm256_add_pd(full, _mm256_mul_pd(va, vb));
    ab = _mm256_add_pd(ab, _mm256_mul_pd(_mm256_loadu_pd(a + x + 1), vb));  // a(x + 1)·b(x)
    ba = _mm256_add_pd(ba, _mm256_mul_pd(va, _mm256_loadu_pd(b + x + 1)));  // a(x)·b(x + 1)
    sa = _mm256_add_pd(sa, va);
  }
  // Each vector's lanes added as (0 + 1) + (2 + 3), in registers.
  const __m256d pairs_fa = _mm256_hadd_pd(full, ab), pairs_bs = _mm256_hadd_pd(ba, sa);
  const __m128d fa = _mm_add_pd(_mm256_castpd256_pd128(pairs_fa), _mm256_extractf128_pd(pairs_fa, 1));
  const __m128d bs = _mm_add_pd(_mm256_castpd256_pd128(pairs_bs), _mm256_extractf128_pd(pairs_bs, 1));
  double f = _mm_cvtsd_f64(fa), lab = _mm_cvtsd_f64(_mm_unpackhi_pd(fa, fa));
  double lba = _mm_cvtsd_f64(bs), s = _mm_cvtsd_f64(_mm_unpackhi_pd(bs, bs));
  _mm256_zeroupper();
  if (x == len && len > 0) lab -= a[len] * b[len - 1], lba -= a[len - 1] * b[len];
  for (; x < len; ++x) {
    f += a[x] * b[x], s += a[x];
    if (x + 1 < len) lab += a[x + 1] * b[x], lba += a[x] * b[x + 1];
  }
  return {static_cast<std::int64_t>(f), static_cast<std::int64_t>(lab), static_cast<std::int64_t>(lba),
          static_cast<std::int64_t>(s)};
}
#endif

RowPair row_pair(const double* a, const double* b, std::uint32_t len) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (use_avx2()) return pair_avx2(a, b, len);
#endif
  return pair_scalar(a, b, len);
}

}  // namespace

RowSample row_sample(const BrickDims& d) {
  // 4096 sampled voxels: a 32^3 brick's quarter holds 7936, a 16^3 brick's
  // 960 (all of its 3375 are taken).
  constexpr std::uint64_t kEnough = 4096;
  const RowSample sparse{2};
  return sampled_voxels(d, sparse) >= kEnough ? sparse : RowSample{};
}

// The moments of the sample's interior rows from a few sums per brick row: the eight
// features of a voxel are four rows (its own, the one before along y, along
// z, along both) at x and at x − 1, so Σ f_i·f_j over a row is a product of
// two whole rows (less one end voxel) or a product at a lag of one voxel; and
// each pair of rows recurs for several interior rows. 14 products per voxel
// instead of 36.
bool brick_moments(const BrickDims& d, const std::uint16_t* u, BrickMoments& out, RowSample sample) {
  if (sampled_voxels(d, sample) < 64) return false;
  out = BrickMoments{};
  const std::uint32_t e = d[0], ey = d[1], ez = d[2];
  const std::size_t sy = e, sz = std::size_t{e} * ey, rows = std::size_t{ey} * ez;
  const std::uint16_t ref = u[sz + sy + 1];
  // The values less ref, as doubles: a row's sums of products stay below
  // 2^40 (at most 256 products below 2^32), exact in a double, whose
  // products vectorise where 64-bit integer ones do not.
  // Kept per thread: a 32^3 brick's 256 KiB, allocated anew for every
  // brick, would be mapped and faulted in anew every time.
  thread_local std::vector<double> values;
  values.resize(sz * ez + 4);  // and values after the last row for row_pair's loads
  double* const v = values.data();
  for (std::size_t i = 0; i < sz * ez; ++i) v[i] = static_cast<double>(std::int32_t{u[i]} - ref);
  for (std::size_t i = sz * ez; i < values.size(); ++i) v[i] = 0;
  auto row = [&](std::uint32_t y, std::uint32_t z) { return v + z * sz + y * sy; };
  auto pair = [&](const double* a, const double* b) { return row_pair(a, b, e); };
  // Per brick row (index z * ey + y): its sum and ends, its product with
  // itself, with the row before it along y, along z, along both, and of the
  // rows (y − 1, z) and (y, z − 1); each only where a sampled row needs it
  // (a sampled row (y, z) needs the rows (y − 1, z) and (y, z − 1) too).
  std::vector<std::int64_t> sum(rows);
  std::vector<RowPair> self(rows), along_y(rows), along_z(rows), diagonal(rows), antidiagonal(rows);
  for (std::uint32_t z = 0; z < ez; ++z)
    for (std::uint32_t y = 0; y < ey; ++y) {
      const std::size_t r = std::size_t{z} * ey + y;
      const double* c = row(y, z);
      const bool odd_y = sample.all() || (y & 1), odd_z = sample.all() || (z & 1);
      self[r] = pair(c, c);  // both lags Σ a(x)·a(x − 1)
      sum[r] = self[r].sum_a;
      if (y > 0 && odd_y) along_y[r] = pair(c, row(y - 1, z));
      if (z > 0 && odd_z) along_z[r] = pair(c, row(y, z - 1));
      if (y > 0 && z > 0 && odd_y && odd_z)
        diagonal[r] = pair(c, row(y - 1, z - 1)), antidiagonal[r] = pair(row(y - 1, z), row(y, z - 1));
    }
  // Feature i is row kRow[i] of (own, y − 1, z − 1, both) at x (kNow) or x − 1.
  static constexpr int kRow[8] = {0, 0, 1, 2, 1, 2, 3, 3};
  static constexpr bool kNow[8] = {true, false, true, true, false, false, true, false};
  for (std::uint32_t z = 1; z < ez; z += sample.step)
    for (std::uint32_t y = 1; y < ey; y += sample.step) {
      const std::size_t r[4] = {std::size_t{z} * ey + y, std::size_t{z} * ey + y - 1, std::size_t{z - 1} * ey + y,
                                std::size_t{z - 1} * ey + y - 1};
      // full[a][b] = Σ_x R_a·R_b, lag[a][b] = Σ_{x ≥ 1} R_a(x)·R_b(x − 1).
      std::int64_t full[4][4], lag[4][4];
      auto set = [&](int a, int b, const RowPair& p) {
        full[a][b] = full[b][a] = p.full;
        lag[a][b] = p.lag_ab, lag[b][a] = p.lag_ba;
      };
      for (int a = 0; a < 4; ++a) set(a, a, self[r[a]]);
      set(0, 1, along_y[r[0]]);
      set(2, 3, along_y[r[2]]);
      set(0, 2, along_z[r[0]]);
      set(1, 3, along_z[r[1]]);
      set(0, 3, diagonal[r[0]]);
      set(1, 2, antidiagonal[r[0]]);
      std::int64_t first[4], last[4];
      for (int a = 0; a < 4; ++a) {
        const double* p = v + (r[a] / ey) * sz + (r[a] % ey) * sy;
        first[a] = static_cast<std::int64_t>(p[0]), last[a] = static_cast<std::int64_t>(p[e - 1]);
      }
      for (int i = 0; i < 8; ++i) {
        const int a = kRow[i];
        out.sum[i] += sum[r[a]] - (kNow[i] ? first[a] : last[a]);
        for (int j = 0; j < 8; ++j) {
          const int b = kRow[j];
          if (kNow[i] && kNow[j])
            out.product[i][j] += full[a][b] - first[a] * first[b];
          else if (!kNow[i] && !kNow[j])
            out.product[i][j] += full[a][b] - last[a] * last[b];
          else
            out.product[i][j] += kNow[i] ? lag[a][b] : lag[b][a];
        }
      }
      out.count += e - 1;
    }
  return true;
}

bool fit_least_squares(const BrickMoments& m, PredictorTaps& out) {
  // Σ (f_a − f_1)(f_b − f_1) from the moments; f_1 is U(x−1), f_0 is U.
  auto centred = [&](int a, int b) {
    return static_cast<double>(m.product[a][b] - m.product[a][1] - m.product[1][b] + m.product[1][1]);
  };
  double ata[36], atb[6];
  for (int r = 0; r < 6; ++r) {
    atb[r] = centred(r + 2, 0);
    for (int k = 0; k < 6; ++k) ata[r * 6 + k] = centred(r + 2, k + 2);
  }
  if (!solve(ata, atb, 6)) return false;
  out = PredictorTaps{};
  out.shift = kLeastSquaresShift;
  std::int32_t rest = 0;
  for (int r = 0; r < 6; ++r) {
    const double scaled = std::nearbyint(atb[r] * (1 << kLeastSquaresShift));
    if (!(std::fabs(scaled) <= 16384)) return false;
    out.t[r + 1] = static_cast<std::int32_t>(scaled);
    rest += out.t[r + 1];
  }
  out.t[0] = (1 << kLeastSquaresShift) - rest;  // the taps sum to exactly 2^shift
  return out.t[0] >= -32768 && out.t[0] <= 32767;
}

bool fit_least_squares_with_level(const BrickDims& d, const std::uint16_t* u, const BrickMoments& m, PredictorTaps& out,
                                  RowSample sample) {
  // The covariance of the neighbours (f_1 .. f_7) and with the value (f_0).
  const double count = static_cast<double>(m.count), sum_v = static_cast<double>(m.sum[0]);
  double cov[49], rhs[7];
  for (int r = 0; r < 7; ++r) {
    const double sum_r = static_cast<double>(m.sum[r + 1]);
    rhs[r] = static_cast<double>(m.product[r + 1][0]) - sum_r * sum_v / count;
    for (int k = r; k < 7; ++k)
      cov[r * 7 + k] = cov[k * 7 + r] =
          static_cast<double>(m.product[r + 1][k + 1]) - sum_r * static_cast<double>(m.sum[k + 1]) / count;
  }
  if (!solve(cov, rhs, 7)) return false;
  out = PredictorTaps{};
  out.shift = kLeastSquaresShift;
  for (int r = 0; r < 7; ++r) {
    const double scaled = std::nearbyint(rhs[r] * (1 << kLeastSquaresShift));
    if (!(std::fabs(scaled) <= 32767)) return false;
    out.t[r] = static_cast<std::int32_t>(scaled);
  }
  // The level: the mean of what the rounded taps leave, over the sample.
  const RowPredictor p(out);
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  std::int64_t left = 0;
  for (std::uint32_t z = 1; z < d[2]; z += sample.step)
    for (std::uint32_t y = 1; y < d[1]; y += sample.step) {
      const std::uint16_t* c = u + z * sz + y * sy;
      const RowNeighbours n{c - sy, c - sz, c - sy - sz};
      left += p.narrow ? level_row<std::int32_t>(p, c, n, d[0]) : level_row<std::int64_t>(p, c, n, d[0]);
    }
  out.bias = static_cast<std::int32_t>(std::nearbyint(static_cast<double>(left) / count));
  return true;
}

}  // namespace ivol::detail
