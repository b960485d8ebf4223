// Codec 3, predicted 16-bit (spec §7.2): exact round trips of any bits, a
// naive decoder written from the spec's formulas as the reference, and
// hostile payloads refused with clear errors.
#include <gtest/gtest.h>
#include <zstd.h>

#include <cmath>
#include <cstring>
#include <random>

#include "ivol/error.hpp"
#include "ivol/predicted_codec.hpp"

namespace {

using ivol::BrickDims;
using ivol::ValueEncoding;

std::size_t count(const BrickDims& d) { return std::size_t{d[0]} * d[1] * d[2]; }

// The spec's decoder, voxel by voxel, as plainly as it is written there.
std::vector<std::uint16_t> reference_decode(const std::vector<std::uint8_t>& payload, const BrickDims& d) {
  const std::size_t n = count(d);
  std::vector<std::uint8_t> planes(2 * n);
  const std::size_t got = ZSTD_decompress(planes.data(), planes.size(), payload.data() + 24, payload.size() - 24);
  EXPECT_EQ(got, planes.size());
  const int map = payload[1], shift = payload[2];
  std::int64_t tap[7];
  for (int k = 0; k < 7; ++k) tap[k] = static_cast<std::int16_t>(payload[4 + 2 * k] | payload[5 + 2 * k] << 8);
  const std::int64_t bias =
      static_cast<std::int32_t>(payload[18] | payload[19] << 8 | payload[20] << 16 | std::uint32_t{payload[21]} << 24);
  std::vector<std::int64_t> u(n);
  auto at = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return u[(z * d[1] + y) * d[0] + x]; };
  auto clamp = [](std::int64_t p) { return std::min<std::int64_t>(65535, std::max<std::int64_t>(0, p)); };
  for (std::int64_t z = 0; z < d[2]; ++z)
    for (std::int64_t y = 0; y < d[1]; ++y)
      for (std::int64_t x = 0; x < d[0]; ++x) {
        std::int64_t p;
        if (x > 0 && y > 0 && z > 0) {
          const std::int64_t s = tap[0] * at(x - 1, y, z) + tap[1] * at(x, y - 1, z) + tap[2] * at(x, y, z - 1) +
                                 tap[3] * at(x - 1, y - 1, z) + tap[4] * at(x - 1, y, z - 1) +
                                 tap[5] * at(x, y - 1, z - 1) + tap[6] * at(x - 1, y - 1, z - 1);
          const std::int64_t r = shift > 0 ? std::int64_t{1} << (shift - 1) : 0;
          p = clamp(static_cast<std::int64_t>(std::floor(static_cast<long double>(s + r) / (1LL << shift))) + bias);
        } else if (x > 0 && y > 0) {
          p = clamp(at(x - 1, y, z) + at(x, y - 1, z) - at(x - 1, y - 1, z));
        } else if (x > 0 && z > 0) {
          p = clamp(at(x - 1, y, z) + at(x, y, z - 1) - at(x - 1, y, z - 1));
        } else if (y > 0 && z > 0) {
          p = clamp(at(x, y - 1, z) + at(x, y, z - 1) - at(x, y - 1, z - 1));
        } else if (x > 0) {
          p = at(x - 1, y, z);
        } else if (y > 0) {
          p = at(x, y - 1, z);
        } else if (z > 0) {
          p = at(x, y, z - 1);
        } else {
          p = 0;
        }
        const std::size_t i = static_cast<std::size_t>((z * d[1] + y) * d[0] + x);
        const std::int64_t zz = planes[i] | planes[n + i] << 8;
        const std::int64_t s = (zz % 2 == 0) ? zz / 2 : -(zz + 1) / 2;
        u[i] = ((p + s) % 65536 + 65536) % 65536;
      }
  std::vector<std::uint16_t> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto v = static_cast<std::uint16_t>(u[i]);
    out[i] = map == 0 ? v : (v >= 0x8000 ? static_cast<std::uint16_t>(v - 0x8000) : static_cast<std::uint16_t>(~v));
  }
  return out;
}

std::vector<std::uint16_t> decode(const std::vector<std::uint8_t>& payload, const BrickDims& d) {
  std::vector<std::uint16_t> out(count(d));
  ivol::decode_predicted(payload.data(), payload.size(), d, out.data());
  return out;
}

void expect_round_trip(const std::vector<std::uint16_t>& values, const BrickDims& d, ValueEncoding e,
                       ivol::PredictedOptions options = {}) {
  const auto payload = ivol::encode_predicted(values.data(), d, e, options);
  EXPECT_EQ(decode(payload, d), values) << d[0] << "x" << d[1] << "x" << d[2];
  EXPECT_EQ(reference_decode(payload, d), values) << d[0] << "x" << d[1] << "x" << d[2];
}

// A smooth CT-like brick: a sphere of one density in another, with noise.
std::vector<std::uint16_t> smooth_brick(const BrickDims& d, ValueEncoding e, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  std::vector<std::uint16_t> v(count(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const float r = std::sqrt(float((x - 12.0) * (x - 12.0) + (y - 14.0) * (y - 14.0) + (z - 9.0) * (z - 9.0)));
        const float m = (r < 10 ? 0.05f : 0.01f) + 0.001f * x + noise(rng);
        if (e == ValueEncoding::UInt16) {
          v[i] = static_cast<std::uint16_t>(std::lround(std::clamp(m * 400000.0f, 0.0f, 65535.0f)));
        } else {  // binary16 of m, by the bits of a float (round toward zero is enough here)
          std::uint32_t f;
          std::memcpy(&f, &m, 4);
          const int exp = int((f >> 23) & 0xFF) - 127 + 15;
          v[i] = exp <= 0 ? std::uint16_t((f >> 16) & 0x8000)
                          : std::uint16_t(((f >> 16) & 0x8000) | (exp << 10) | ((f >> 13) & 0x3FF));
        }
      }
  return v;
}

TEST(PredictedCodec, RandomBitsRoundTripInEveryBrickShape) {
  std::mt19937 rng(7);
  const BrickDims shapes[] = {{1, 1, 1},  {2, 1, 1},  {1, 1, 9},  {1, 7, 1},    {5, 3, 7},
                              {32, 1, 1}, {3, 32, 2}, {17, 9, 1}, {32, 32, 32}, {32, 32, 5}};
  for (const auto& d : shapes)
    for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16}) {
      std::vector<std::uint16_t> v(count(d));
      for (auto& x : v) x = static_cast<std::uint16_t>(rng());
      expect_round_trip(v, d, e);
    }
}

TEST(PredictedCodec, SmoothBricksRoundTripWithEveryTapChoice) {
  using T = ivol::PredictedOptions::Taps;
  for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16})
    for (T taps : {T::Best, T::Lorenzo, T::LeastSquares})
      for (const BrickDims& d : {BrickDims{32, 32, 32}, BrickDims{32, 7, 19}, BrickDims{4, 4, 4}}) {
        ivol::PredictedOptions o;
        o.taps = taps;
        expect_round_trip(smooth_brick(d, e, 3), d, e, o);
      }
}

TEST(PredictedCodec, KeepsNegativeZeroNaNPayloadsAndInfinities) {
  const BrickDims d{8, 4, 3};
  std::vector<std::uint16_t> v(count(d), 0x3C00);
  const std::uint16_t special[] = {0x8000, 0x0000, 0x7E00, 0x7C01, 0xFE5A, 0x7FFF, 0xFFFF, 0x7C00, 0xFC00, 0x0001};
  for (std::size_t i = 0; i < v.size(); ++i)
    if (i % 3 == 0) v[i] = special[i % 10];
  expect_round_trip(v, d, ValueEncoding::Binary16);
  expect_round_trip(v, d, ValueEncoding::UInt16);
  // A brick of nothing but -0 stays -0 in every voxel.
  std::vector<std::uint16_t> zeros(count(d), 0x8000);
  expect_round_trip(zeros, d, ValueEncoding::Binary16);
}

TEST(PredictedCodec, APlaneIsPredictedExactly) {
  // v = 1000 + 3x + 5y + 7z: every face and Lorenzo predictor is exact, so
  // all residuals but the first are 0 and the payload is tiny.
  const BrickDims d{32, 32, 32};
  std::vector<std::uint16_t> v(count(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x) v[i++] = static_cast<std::uint16_t>(1000 + 3 * x + 5 * y + 7 * z);
  const auto payload = ivol::encode_predicted(v.data(), d, ValueEncoding::UInt16);
  EXPECT_LT(payload.size(), 200u);
  std::vector<std::uint8_t> planes(2 * count(d));
  ASSERT_EQ(ZSTD_decompress(planes.data(), planes.size(), payload.data() + 24, payload.size() - 24), planes.size());
  // Voxel 0 is predicted as 0: zigzag(1000) = 2000 = 0x07D0; x = 1 from x = 0 (3 -> 6), y = 1 (5 -> 10).
  EXPECT_EQ(planes[0], 0xD0);
  EXPECT_EQ(planes[count(d)], 0x07);
  EXPECT_EQ(planes[1], 6);
  EXPECT_EQ(planes[32], 10);
  for (std::size_t k = 33 * 32 + 1; k < count(d); ++k)
    if ((k % 32) && (k / 32 % 32) && k / 1024) ASSERT_EQ(planes[k], 0) << k;
  EXPECT_EQ(decode(payload, d), v);
}

TEST(PredictedCodec, SmoothBinary16IsSmallerThanZstdOverBytePlanes) {
  const BrickDims d{32, 32, 32};
  const auto v = smooth_brick(d, ValueEncoding::Binary16, 11);
  const auto payload = ivol::encode_predicted(v.data(), d, ValueEncoding::Binary16);
  std::vector<std::uint8_t> planes(2 * v.size());
  for (std::size_t i = 0; i < v.size(); ++i) planes[i] = v[i] & 0xFF, planes[v.size() + i] = v[i] >> 8;
  std::vector<std::uint8_t> frame(ZSTD_compressBound(planes.size()));
  const std::size_t codec2 = ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), 3);
  EXPECT_LT(payload.size(), codec2);
}

TEST(PredictedCodec, ArbitraryTapsDecodeAsTheSpecSays) {
  // Hostile but valid headers: extreme taps and shifts, random residuals.
  std::mt19937 rng(99);
  const BrickDims d{6, 5, 4};
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::uint8_t> planes(2 * count(d));
    for (auto& b : planes) b = static_cast<std::uint8_t>(rng());
    std::vector<std::uint8_t> payload(24, 0);
    payload[0] = 1;
    payload[1] = rng() % 2;
    payload[2] = rng() % 16;
    payload[3] = 1;
    for (int k = 0; k < 18; ++k)
      payload[4 + k] = trial % 4 == 0 ? (k % 2 ? 0x7F : 0xFF) : static_cast<std::uint8_t>(rng());
    std::vector<std::uint8_t> frame(ZSTD_compressBound(planes.size()));
    frame.resize(ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), 1));
    payload.insert(payload.end(), frame.begin(), frame.end());
    ASSERT_EQ(decode(payload, d), reference_decode(payload, d)) << trial;
  }
}

TEST(PredictedCodec, TapsAtTheEdgeOf32BitSumsDecodeAsTheSpecSays) {
  // The decoder sums in 32 bits when the taps and level allow it (Σ|t| up
  // to 65534, |level| below 2^31 less the prediction's reach) and in 64 bits
  // otherwise: taps and levels on either side of that line, against the
  // spec's formulas in 64 bits.
  std::mt19937 rng(2024);
  const BrickDims d{9, 6, 5};
  const std::int64_t levels[] = {0, 1000, -70000, 1 << 20, -(1 << 29), (1LL << 31) - 1, -(1LL << 31), 1 << 30};
  for (int trial = 0; trial < 400; ++trial) {
    std::vector<std::uint8_t> planes(2 * count(d));
    for (auto& b : planes) b = static_cast<std::uint8_t>(rng() % 4 ? rng() % 8 : rng());  // mostly small residuals
    std::vector<std::uint8_t> payload(24, 0);
    payload[0] = 1;
    payload[1] = rng() % 2;
    payload[2] = static_cast<std::uint8_t>(trial % 16);
    payload[3] = 1;
    const int reach = trial % 2 ? 9362 : 9363;  // 7 * 9362 = 65534
    for (int k = 0; k < 7; ++k) {
      const auto tap = static_cast<std::uint16_t>(static_cast<std::int16_t>(
          trial % 5 == 0 ? (k % 2 ? -reach : reach) : static_cast<int>(rng() % (2 * reach + 1)) - reach));
      payload[4 + 2 * k] = static_cast<std::uint8_t>(tap), payload[5 + 2 * k] = static_cast<std::uint8_t>(tap >> 8);
    }
    const auto level = static_cast<std::uint32_t>(static_cast<std::int32_t>(levels[trial % 8]));
    for (int k = 0; k < 4; ++k) payload[18 + k] = static_cast<std::uint8_t>(level >> (8 * k));
    std::vector<std::uint8_t> frame(ZSTD_compressBound(planes.size()));
    frame.resize(ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), 1));
    payload.insert(payload.end(), frame.begin(), frame.end());
    ASSERT_EQ(decode(payload, d), reference_decode(payload, d)) << trial;
  }
}

void expect_refused(const std::vector<std::uint8_t>& payload, const BrickDims& d, ivol::ErrorClass c,
                    const std::string& text) {
  try {
    decode(payload, d);
    FAIL() << "accepted: " << text;
  } catch (const ivol::Error& e) {
    EXPECT_EQ(e.error_class(), c) << e.what();
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(PredictedCodec, HostilePayloadsAreRefused) {
  const BrickDims d{8, 8, 8};
  const auto v = smooth_brick(d, ValueEncoding::UInt16, 5);
  const auto good = ivol::encode_predicted(v.data(), d, ValueEncoding::UInt16);
  using C = ivol::ErrorClass;
  expect_refused({}, d, C::Malformed, "shorter than the codec header");
  expect_refused(std::vector<std::uint8_t>(good.begin(), good.begin() + 23), d, C::Malformed, "shorter");
  auto p = good;
  p[0] = 2;
  expect_refused(p, d, C::UnsupportedFeature, "predictor 2");
  p = good, p[1] = 2;
  expect_refused(p, d, C::Malformed, "value map 2");
  p = good, p[2] = 16;
  expect_refused(p, d, C::Malformed, "shift 16");
  p = good, p[3] = 0;
  expect_refused(p, d, C::UnsupportedFeature, "entropy coder 0");
  p = good, p[23] = 1;
  expect_refused(p, d, C::Malformed, "reserved");
  p = good, p.push_back(0);
  expect_refused(p, d, C::Malformed, "exactly one complete zstd frame");
  p = std::vector<std::uint8_t>(good.begin(), good.end() - 1);
  expect_refused(p, d, C::Malformed, "zstd frame");
  p = good, p[24] ^= 0xFF;
  expect_refused(p, d, C::Malformed, "not a zstd frame");
  // A frame of the wrong brick: 7 x 8 x 8 values are not 8 x 8 x 8.
  expect_refused(good, BrickDims{7, 8, 8}, C::Malformed, "the brick needs");
  // Damage anywhere: only ivol::Error, never a crash or a wrong size.
  std::mt19937 rng(1);
  for (int trial = 0; trial < 2000; ++trial) {
    p = good;
    const int flips = 1 + rng() % 4;
    for (int k = 0; k < flips; ++k) p[rng() % p.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    if (rng() % 3 == 0) p.resize(rng() % p.size());
    try {
      decode(p, d);
    } catch (const ivol::Error&) {
    }
  }
}

}  // namespace
