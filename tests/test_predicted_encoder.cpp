// Codec 3's encoder (libformat/src/predicted_*) against a plain one: the
// first implementation of the spec's arithmetic, voxel by voxel in 64 bits
// and least squares accumulated voxel by voxel in doubles, kept here as the
// reference. The fast encoder (32-bit vectorised rows, moments from row
// products) must choose the same taps and level and leave the same
// residuals, brick for brick: the same file bytes as before it was fast.
// Both fit and judge on the same rows: a quarter of a large brick's (odd y
// and odd z), every row of a small one.
#include <gtest/gtest.h>
#include <zstd.h>

#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "ivol/predicted_codec.hpp"

namespace {

using ivol::BrickDims;
using ivol::ValueEncoding;

struct Taps {
  unsigned shift = 0;
  std::array<std::int32_t, 7> t{};
  std::int32_t bias = 0;
};
constexpr Taps kLorenzo{0, {1, 1, 1, -1, -1, -1, 1}, 0};

std::int64_t clamp_u16(std::int64_t p) { return p < 0 ? 0 : p > 65535 ? 65535 : p; }

std::int64_t face_prediction(const std::uint16_t* u, std::size_t i, bool ax, bool ay, bool az, std::ptrdiff_t sy,
                             std::ptrdiff_t sz) {
  const int axes = int{ax} + int{ay} + int{az};
  if (axes == 0) return 0;
  const auto at = static_cast<std::ptrdiff_t>(i);
  if (axes == 1) return u[at - (ax ? 1 : ay ? sy : sz)];
  const std::ptrdiff_t s1 = ax ? 1 : sy;
  const std::ptrdiff_t s2 = az ? sz : sy;
  return clamp_u16(std::int64_t{u[at - s1]} + u[at - s2] - u[at - s1 - s2]);
}

template <class F>
void walk_brick(const BrickDims& d, const Taps& taps, const std::uint16_t* u, F&& at) {
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  const std::int64_t round = taps.shift ? std::int64_t{1} << (taps.shift - 1) : 0;
  const auto& t = taps.t;
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        if (x == 0 || y == 0 || z == 0) {
          at(i, static_cast<std::uint16_t>(face_prediction(u, i, x > 0, y > 0, z > 0, sy, sz)));
          continue;
        }
        const std::uint16_t* c = u + i;
        const std::int64_t sum = t[0] * std::int64_t{c[-1]} + t[1] * std::int64_t{c[-sy]} +
                                 t[2] * std::int64_t{c[-sz]} + t[3] * std::int64_t{c[-1 - sy]} +
                                 t[4] * std::int64_t{c[-1 - sz]} + t[5] * std::int64_t{c[-sy - sz]} +
                                 t[6] * std::int64_t{c[-1 - sy - sz]};
        at(i, static_cast<std::uint16_t>(clamp_u16(((sum + round) >> taps.shift) + taps.bias)));
      }
}

std::uint16_t zigzag(std::uint16_t value, std::uint16_t prediction) {
  const auto s = static_cast<std::int16_t>(static_cast<std::uint16_t>(value - prediction));
  return s >= 0 ? static_cast<std::uint16_t>(2 * s) : static_cast<std::uint16_t>(-2 * std::int32_t{s} - 1);
}

constexpr unsigned kLeastSquaresShift = 12;

// The rows the encoder fits and judges taps on: those of odd y and odd z
// when they hold 4096 interior voxels or more, else every interior row.
struct Sample {
  std::uint32_t step = 1;
};
Sample sample_of(const ivol::BrickDims& d) {
  if (d[0] < 2) return {};
  const std::uint64_t quarter = std::uint64_t{d[0] - 1} * (d[1] / 2) * (d[2] / 2);
  return quarter >= 4096 ? Sample{2} : Sample{};
}

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

// Least-squares taps for the brick's interior voxels, constrained to sum to
// one (so that rounding them to integers costs nothing on a constant level):
// the value minus its x neighbour is fitted on the other six neighbours minus
// the x neighbour. False when too few voxels or the fit is degenerate.
bool fit_least_squares(const ivol::BrickDims& d, const std::uint16_t* u, Taps& out) {
  if (d[0] < 2 || d[1] < 2 || d[2] < 2 || (d[0] - 1) * std::uint64_t{d[1] - 1} * (d[2] - 1) < 64) return false;
  const std::uint32_t step = sample_of(d).step;
  // Signed strides: c[-sy] steps back, which unsigned arithmetic would wrap.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  double ata[36] = {}, atb[6] = {};
  for (std::uint32_t z = 1; z < d[2]; z += step)
    for (std::uint32_t y = 1; y < d[1]; y += step) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        const double a = c[-1];
        const double n[6] = {c[-sy] - a,     c[-sz] - a,      c[-1 - sy] - a,
                             c[-1 - sz] - a, c[-sy - sz] - a, c[-1 - sy - sz] - a};
        const double v = c[0] - a;
        for (int r = 0; r < 6; ++r) {
          atb[r] += n[r] * v;
          for (int k = r; k < 6; ++k) ata[r * 6 + k] += n[r] * n[k];
        }
      }
    }
  for (int r = 0; r < 6; ++r)
    for (int k = 0; k < r; ++k) ata[r * 6 + k] = ata[k * 6 + r];
  if (!solve(ata, atb, 6)) return false;
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

// Least-squares taps with a level (intercept), for bricks where noise
// dominates: predicting every voxel from its neighbours' sum would add their
// noise, predicting the level does not. Fitted on values less the brick's
// first interior voxel (so that the sums keep their precision); the level is
// computed after the taps are rounded, so their rounding costs nothing.
bool fit_least_squares_with_level(const ivol::BrickDims& d, const std::uint16_t* u, Taps& out) {
  if (d[0] < 2 || d[1] < 2 || d[2] < 2 || (d[0] - 1) * std::uint64_t{d[1] - 1} * (d[2] - 1) < 64) return false;
  const std::uint32_t step = sample_of(d).step;
  // Signed strides: c[-sy] steps back, which unsigned arithmetic would wrap.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  const double ref = u[sz + sy + 1];
  double sum_n[7] = {}, sum_v = 0, nn[49] = {}, nv[7] = {}, count = 0;
  auto neighbours = [&](const std::uint16_t* c, double* n) {
    n[0] = c[-1] - ref, n[1] = c[-sy] - ref, n[2] = c[-sz] - ref, n[3] = c[-1 - sy] - ref;
    n[4] = c[-1 - sz] - ref, n[5] = c[-sy - sz] - ref, n[6] = c[-1 - sy - sz] - ref;
  };
  for (std::uint32_t z = 1; z < d[2]; z += step)
    for (std::uint32_t y = 1; y < d[1]; y += step) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        double n[7];
        neighbours(c, n);
        const double v = c[0] - ref;
        count += 1, sum_v += v;
        for (int r = 0; r < 7; ++r) {
          sum_n[r] += n[r], nv[r] += n[r] * v;
          for (int k = r; k < 7; ++k) nn[r * 7 + k] += n[r] * n[k];
        }
      }
    }
  double cov[49], rhs[7];
  for (int r = 0; r < 7; ++r) {
    rhs[r] = nv[r] - sum_n[r] * sum_v / count;
    for (int k = r; k < 7; ++k) cov[r * 7 + k] = cov[k * 7 + r] = nn[r * 7 + k] - sum_n[r] * sum_n[k] / count;
  }
  if (!solve(cov, rhs, 7)) return false;
  out.shift = kLeastSquaresShift;
  for (int r = 0; r < 7; ++r) {
    const double scaled = std::nearbyint(rhs[r] * (1 << kLeastSquaresShift));
    if (!(std::fabs(scaled) <= 32767)) return false;
    out.t[r] = static_cast<std::int32_t>(scaled);
  }
  // The level: the mean of what the rounded taps leave, over the interior.
  out.bias = 0;
  double left = 0;
  const std::int64_t round = std::int64_t{1} << (kLeastSquaresShift - 1);
  for (std::uint32_t z = 1; z < d[2]; z += step)
    for (std::uint32_t y = 1; y < d[1]; y += step) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        const std::int64_t sum = out.t[0] * std::int64_t{c[-1]} + out.t[1] * std::int64_t{c[-sy]} +
                                 out.t[2] * std::int64_t{c[-sz]} + out.t[3] * std::int64_t{c[-1 - sy]} +
                                 out.t[4] * std::int64_t{c[-1 - sz]} + out.t[5] * std::int64_t{c[-sy - sz]} +
                                 out.t[6] * std::int64_t{c[-1 - sy - sz]};
        left += static_cast<double>(c[0] - ((sum + round) >> kLeastSquaresShift));
      }
    }
  out.bias = static_cast<std::int32_t>(std::nearbyint(left / count));
  return true;
}

// Sum of the residuals' bit lengths (about what they cost coded) over the
// sample's interior voxels: what the candidate taps are judged by.
std::uint64_t residual_cost(const ivol::BrickDims& d, const Taps& taps, const std::uint16_t* u) {
  const std::uint32_t step = sample_of(d).step;
  std::uint64_t cost = 0;
  walk_brick(d, taps, const_cast<std::uint16_t*>(u), [&](std::size_t i, std::uint16_t p) {
    const std::size_t x = i % d[0], y = i / d[0] % d[1], z = i / (std::size_t{d[0]} * d[1]);
    if (x == 0 || y == 0 || z == 0 || (step == 2 && !(y % 2 == 1 && z % 2 == 1))) return;
    for (unsigned r = zigzag(u[i], p); r != 0; r >>= 1) ++cost;
  });
  return cost;
}

struct Reference {
  Taps taps;
  std::uint8_t map;
  std::vector<std::uint8_t> planes;
};

Reference reference_encode(const std::vector<std::uint16_t>& values, const BrickDims& dims, ValueEncoding e) {
  const std::size_t n = values.size();
  Reference r;
  r.map = e == ValueEncoding::Binary16 ? 1 : 0;
  std::vector<std::uint16_t> u(n);
  for (std::size_t i = 0; i < n; ++i)
    u[i] = r.map == 0             ? values[i]
           : (values[i] & 0x8000) ? static_cast<std::uint16_t>(values[i] ^ 0xFFFF)
                                  : static_cast<std::uint16_t>(values[i] | 0x8000);
  r.taps = kLorenzo;
  std::uint64_t best = residual_cost(dims, kLorenzo, u.data());
  Taps fitted;
  if (fit_least_squares(dims, u.data(), fitted))
    if (const std::uint64_t cost = residual_cost(dims, fitted, u.data()); cost < best) best = cost, r.taps = fitted;
  if (fit_least_squares_with_level(dims, u.data(), fitted))
    if (const std::uint64_t cost = residual_cost(dims, fitted, u.data()); cost < best) best = cost, r.taps = fitted;
  r.planes.resize(2 * n);
  walk_brick(dims, r.taps, u.data(), [&](std::size_t i, std::uint16_t p) {
    const std::uint16_t z = zigzag(u[i], p);
    r.planes[i] = static_cast<std::uint8_t>(z);
    r.planes[n + i] = static_cast<std::uint8_t>(z >> 8);
  });
  return r;
}

void expect_same_as_reference(const std::vector<std::uint16_t>& v, const BrickDims& d, ValueEncoding e,
                              const std::string& what) {
  const Reference r = reference_encode(v, d, e);
  ivol::PredictedOptions zstd_planes;  // the residuals as byte planes, to compare them
  zstd_planes.entropy = ivol::PredictedOptions::Entropy::ZstdPlanes;
  const auto payload = ivol::encode_predicted(v.data(), d, e, zstd_planes);
  ASSERT_GE(payload.size(), 24u) << what;
  EXPECT_EQ(payload[1], r.map) << what;
  EXPECT_EQ(payload[2], r.taps.shift) << what;
  for (int k = 0; k < 7; ++k)
    EXPECT_EQ(static_cast<std::int16_t>(payload[4 + 2 * k] | payload[5 + 2 * k] << 8), r.taps.t[k])
        << what << ", tap " << k;
  std::int32_t bias;
  std::memcpy(&bias, payload.data() + 18, 4);  // little-endian hosts only, as the whole test suite
  EXPECT_EQ(bias, r.taps.bias) << what;
  std::vector<std::uint8_t> planes(r.planes.size());
  ASSERT_EQ(ZSTD_decompress(planes.data(), planes.size(), payload.data() + 24, payload.size() - 24), planes.size())
      << what;
  EXPECT_TRUE(planes == r.planes) << what << ": the residuals differ";
}

// A CT-like brick: a sphere of one density in another, a gradient, noise
// of the given strength, as uint16 codes or binary16 bits.
std::vector<std::uint16_t> ct_brick(const BrickDims& d, ValueEncoding e, float noise_sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, noise_sigma);
  std::uniform_real_distribution<float> centre(0.0f, 32.0f);
  const float cx = centre(rng), cy = centre(rng), cz = centre(rng);
  std::vector<std::uint16_t> v(std::size_t{d[0]} * d[1] * d[2]);
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const float r = std::sqrt((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz));
        const float m = (r < 10 ? 0.05f : 0.01f) + 0.001f * x - 0.0007f * z + noise(rng);
        if (e == ValueEncoding::UInt16) {
          v[i] = static_cast<std::uint16_t>(std::lround(std::clamp(m * 400000.0f, 0.0f, 65535.0f)));
        } else {  // binary16 of m, by the bits of a float (truncated), both signs
          std::uint32_t f;
          std::memcpy(&f, &m, 4);
          const int exp = int((f >> 23) & 0xFF) - 127 + 15;
          v[i] = exp <= 0 ? std::uint16_t((f >> 16) & 0x8000)
                          : std::uint16_t(((f >> 16) & 0x8000) | (exp << 10) | ((f >> 13) & 0x3FF));
        }
      }
  return v;
}

TEST(PredictedEncoder, ChoosesTheReferenceTapsOnCtLikeBricks) {
  // 32^3 and 33x33x17 (exactly 4096 sampled voxels) are fitted and judged
  // on a quarter of their rows, the others on all.
  const BrickDims shapes[] = {{32, 32, 32}, {33, 33, 17}, {32, 7, 19}, {5, 5, 5}, {16, 16, 16}, {64, 8, 8}, {3, 40, 2}};
  int checked = 0;
  for (const BrickDims& d : shapes)
    for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16})
      for (float sigma : {0.0f, 0.0005f, 0.002f, 0.02f})
        for (unsigned seed : {1u, 2u}) {
          expect_same_as_reference(ct_brick(d, e, sigma, seed), d, e,
                                   std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]) +
                                       (e == ValueEncoding::UInt16 ? " uint16" : " binary16") + " sigma " +
                                       std::to_string(sigma) + " seed " + std::to_string(seed));
          ++checked;
        }
  EXPECT_EQ(checked, 7 * 2 * 4 * 2);
}

TEST(PredictedEncoder, ChoosesTheReferenceTapsOnExtremeBricks) {
  std::mt19937 rng(5);
  const BrickDims d{32, 16, 16};
  const std::size_t n = std::size_t{d[0]} * d[1] * d[2];
  std::vector<std::uint16_t> v(n);
  // Random bits: the full range in every neighbour (64-bit sums in the fit).
  for (auto& x : v) x = static_cast<std::uint16_t>(rng());
  expect_same_as_reference(v, d, ValueEncoding::UInt16, "random bits");
  expect_same_as_reference(v, d, ValueEncoding::Binary16, "random bits, binary16");
  // Two levels 0 and 65535 in a checkerboard: the largest products.
  for (std::size_t i = 0; i < n; ++i) v[i] = ((i + i / d[0] + i / (d[0] * d[1])) % 2) ? 65535 : 0;
  expect_same_as_reference(v, d, ValueEncoding::UInt16, "checkerboard");
  // Noise around a level near either end of the range, where clamping acts.
  for (std::uint16_t level : {std::uint16_t{3}, std::uint16_t{65530}}) {
    for (auto& x : v) x = static_cast<std::uint16_t>(std::clamp<int>(level + int(rng() % 9) - 4, 0, 65535));
    expect_same_as_reference(v, d, ValueEncoding::UInt16, "noise at " + std::to_string(level));
  }
  // Saw teeth along x: least squares with large taps.
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint16_t>((i % d[0]) % 3 * 20000 + (i / d[0]) % 7);
  expect_same_as_reference(v, d, ValueEncoding::UInt16, "saw teeth");
}

}  // namespace
