// Least-squares taps for codec 3 (spec §7.2). Both fits come from one pass
// over the brick (BrickMoments): the sums are exact integers, so they are the
// same whatever the order of summation, and so are the taps.
#include "predicted_fit.hpp"

#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

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

bool enough_interior(const BrickDims& d) {
  return d[0] >= 2 && d[1] >= 2 && d[2] >= 2 && (d[0] - 1) * std::uint64_t{d[1] - 1} * (d[2] - 1) >= 64;
}

// Σ a[x]·b[x] (or Σ a[x]) over x < len, in four independent sums (which
// the compiler may keep in vector lanes): exact for integers below 2^53.
double exact_sum(const double* a, const double* b, std::uint32_t len, bool products) {
  double s[4] = {};
  std::uint32_t x = 0;
  if (products)
    for (; x + 4 <= len; x += 4)
      for (int k = 0; k < 4; ++k) s[k] += a[x + k] * b[x + k];
  else
    for (; x + 4 <= len; x += 4)
      for (int k = 0; k < 4; ++k) s[k] += a[x + k];
  for (; x < len; ++x) s[0] += products ? a[x] * b[x] : a[x];
  return (s[0] + s[1]) + (s[2] + s[3]);
}

}  // namespace

bool brick_moments(const BrickDims& d, const std::uint16_t* u, BrickMoments& out) {
  if (!enough_interior(d)) return false;
  out = BrickMoments{};
  // Signed strides: a step back along y or z is a negative offset.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  const double ref = u[sz + sy + 1];
  // One row's features, f_i at x in feature[i][x - 1]; a row's sums stay
  // below 2^40 (at most 255 products below 2^32), exact in a double, whose
  // products vectorise where 64-bit integer ones do not.
  const std::uint32_t len = d[0] - 1;
  std::vector<double> features(8 * std::size_t{len});
  for (std::uint32_t z = 1; z < d[2]; ++z)
    for (std::uint32_t y = 1; y < d[1]; ++y) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      const std::uint16_t* rows[8] = {c, c - 1, c - sy, c - sz, c - 1 - sy, c - 1 - sz, c - sy - sz, c - 1 - sy - sz};
      for (int i = 0; i < 8; ++i) {
        double* f = features.data() + i * std::size_t{len};
        for (std::uint32_t x = 0; x < len; ++x) f[x] = rows[i][x] - ref;
      }
      for (int i = 0; i < 8; ++i) {
        const double* fi = features.data() + i * std::size_t{len};
        out.sum[i] += static_cast<std::int64_t>(exact_sum(fi, fi, len, false));
        for (int j = i; j < 8; ++j) {
          const auto product =
              static_cast<std::int64_t>(exact_sum(fi, features.data() + j * std::size_t{len}, len, true));
          out.product[i][j] += product;
          if (j != i) out.product[j][i] += product;
        }
      }
      out.count += len;
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

bool fit_least_squares_with_level(const BrickDims& d, const std::uint16_t* u, const BrickMoments& m,
                                  PredictorTaps& out) {
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
  // The level: the mean of what the rounded taps leave, over the interior.
  const RowPredictor p(out);
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  std::int64_t left = 0;
  for (std::uint32_t z = 1; z < d[2]; ++z)
    for (std::uint32_t y = 1; y < d[1]; ++y) {
      const std::uint16_t* c = u + z * sz + y * sy;
      const RowNeighbours n{c - sy, c - sz, c - sy - sz};
      left += p.narrow ? level_row<std::int32_t>(p, c, n, d[0]) : level_row<std::int64_t>(p, c, n, d[0]);
    }
  out.bias = static_cast<std::int32_t>(std::nearbyint(static_cast<double>(left) / count));
  return true;
}

}  // namespace ivol::detail
