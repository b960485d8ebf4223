// Codec 3, predicted 16-bit (spec §7.2): exact round trips of any bits, a
// naive decoder written from the spec's formulas as the reference, and
// hostile payloads refused with clear errors.
#include <gtest/gtest.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "ivol/error.hpp"
#include "ivol/predicted_codec.hpp"
#include "residual_tokens.hpp"
#include "spec_coder3.hpp"

namespace {

using ivol::BrickDims;
using ivol::ValueEncoding;

std::size_t count(const BrickDims& d) { return std::size_t{d[0]} * d[1] * d[2]; }

std::uint32_t le32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

// Entropy coder 2 (spec §7.2.1) as plainly as it is written there: every
// voxel's neighbours looked up by coordinates, the token found by walking
// the cumulative frequencies, tables made with the spec's arithmetic. Fails
// the test (and returns what it has) where a check of the spec fails.
std::vector<std::uint8_t> spec_token_planes(const std::uint8_t* b, std::size_t size, const BrickDims& d) {
  const std::size_t n = count(d);
  std::vector<std::uint8_t> planes(2 * n);
  if (size < 4) return ADD_FAILURE() << "no length", planes;
  const std::uint64_t R = le32(b);
  if (R < 8 || R > size - 4) return ADD_FAILURE() << "R = " << R, planes;
  const std::uint8_t* stream = b + 4;
  struct Context {
    std::uint64_t c[32], T = 32, m = 0;
    std::uint64_t f[32];
    void make() {
      const std::uint64_t r4 = (std::uint64_t{1} << 44) / T;
      std::uint64_t sum = 0;
      for (int t = 0; t < 32; ++t) f[t] = std::max<std::uint64_t>(1, (c[t] * r4) >> 32), sum += f[t];
      int largest = 0;
      for (int t = 1; t < 32; ++t)
        if (f[t] > f[largest]) largest = t;
      f[largest] = f[largest] + 4096 - sum;
    }
  };
  std::vector<Context> ctx(12);
  for (auto& k : ctx) {
    for (auto& c : k.c) c = 1;
    k.make();
  }
  std::uint64_t X[2] = {le32(stream), le32(stream + 4)};
  for (std::uint64_t x : X) {
    EXPECT_GE(x, 1u << 23);
    EXPECT_LT(x, 1u << 31);
  }
  std::size_t pos = 8;
  std::vector<int> B(n, 0), token(n, 0);
  auto length_at = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    if (x < 0 || y < 0 || z < 0 || x >= d[0] || y >= d[1] || z >= d[2]) return 0;
    return B[static_cast<std::size_t>((z * d[1] + y) * d[0] + x)];
  };
  for (std::int64_t z = 0, i = 0; z < d[2]; ++z)
    for (std::int64_t y = 0; y < d[1]; ++y)
      for (std::int64_t x = 0; x < d[0]; ++x, ++i) {
        const int s = 2 * length_at(x, y - 1, z) + length_at(x, y, z - 1) + length_at(x - 1, y - 1, z) +
                      length_at(x + 1, y - 1, z);
        Context& k = ctx[std::min(11, (s + 2) / 5)];
        std::uint64_t& state = X[i % 2];
        const std::uint64_t slot = state % 4096;
        int t = 0;
        std::uint64_t start = 0;
        while (slot >= start + k.f[t]) start += k.f[t++];
        state = k.f[t] * (state / 4096) + slot - start;
        while (state < (1u << 23)) {
          if (pos >= R) return ADD_FAILURE() << "the stream ends early", planes;
          state = 256 * state + stream[pos++];
        }
        k.c[t] += 16, k.T += 16, k.m += 1;
        if ((k.m >= 4 && (k.m & (k.m - 1)) == 0) || k.m % 128 == 0) k.make();
        token[static_cast<std::size_t>(i)] = t;
        B[static_cast<std::size_t>(i)] = t < 2 ? t : (t >> 1) + 1;
      }
  EXPECT_EQ(X[0], 1u << 23);
  EXPECT_EQ(X[1], 1u << 23);
  EXPECT_EQ(pos, R);
  const std::uint8_t* bits = stream + R;
  const std::size_t bits_size = size - 4 - R;
  std::size_t j = 0;
  auto bit = [&](std::size_t at) { return at / 8 < bits_size ? (bits[at / 8] >> (at % 8)) & 1 : 0; };
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t z = static_cast<std::uint32_t>(token[i]);
    if (token[i] >= 2) {
      const int e = B[i] - 2;
      std::uint32_t w = 0;
      for (int q = 0; q < e; ++q) w |= static_cast<std::uint32_t>(bit(j++)) << q;
      z = ((2u + (token[i] & 1)) << e) + w;
    }
    planes[i] = static_cast<std::uint8_t>(z);
    planes[n + i] = static_cast<std::uint8_t>(z >> 8);
  }
  EXPECT_EQ(bits_size, (j + 7) / 8);
  for (std::size_t at = j; at < 8 * bits_size; ++at) EXPECT_EQ(bit(at), 0) << "padding bit " << at;
  return planes;
}

// The spec's decoder, voxel by voxel, as plainly as it is written there.
std::vector<std::uint16_t> reference_decode(const std::vector<std::uint8_t>& payload, const BrickDims& d) {
  const std::size_t n = count(d);
  std::vector<std::uint8_t> planes(2 * n);
  if (payload[3] == 2) {
    planes = spec_token_planes(payload.data() + 24, payload.size() - 24, d);
  } else if (payload[3] == 3) {
    const auto z = ivol::test::spec_coder3_decode(payload.data() + 24, payload.size() - 24, d);
    for (std::size_t i = 0; i < n; ++i)
      planes[i] = static_cast<std::uint8_t>(z[i]), planes[n + i] = static_cast<std::uint8_t>(z[i] >> 8);
  } else {
    const std::size_t got = ZSTD_decompress(planes.data(), planes.size(), payload.data() + 24, payload.size() - 24);
    EXPECT_EQ(got, planes.size());
  }
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
  ivol::PredictedOptions zstd_planes;
  zstd_planes.entropy = ivol::PredictedOptions::Entropy::ZstdPlanes;
  const auto payload = ivol::encode_predicted(v.data(), d, ValueEncoding::UInt16, zstd_planes);
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
  // to 65534, and the level times 2^s, which decode_row adds before the
  // shift, within what 32 bits leave over) and in 64 bits otherwise: taps,
  // levels and shifts on either side of that line, against the spec's
  // formulas in 64 bits. (Deciding on the taps alone fails here.)
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
  ivol::PredictedOptions zstd_planes;
  zstd_planes.entropy = ivol::PredictedOptions::Entropy::ZstdPlanes;
  const auto good = ivol::encode_predicted(v.data(), d, ValueEncoding::UInt16, zstd_planes);
  ASSERT_EQ(good[3], 1);
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
  p = good, p[3] = 4;
  expect_refused(p, d, C::UnsupportedFeature, "entropy coder 4");
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

using Entropy = ivol::PredictedOptions::Entropy;

std::vector<std::uint8_t> encode_with(const std::vector<std::uint16_t>& v, const BrickDims& d, ValueEncoding e,
                                      Entropy entropy) {
  ivol::PredictedOptions o;
  o.entropy = entropy;
  return ivol::encode_predicted(v.data(), d, e, o);
}

// The writer's rule: coder 2, and coder 1 where coder 2 spends under a bit
// a voxel or the brick is small (under 4096 voxels) and coder 1 is smaller.
TEST(PredictedCodec, TheWriterTriesZstdWhereTokensSpendUnderABitAVoxel) {
  auto bits_per_voxel = [](const std::vector<std::uint8_t>& payload, const BrickDims& d) {
    return 8.0 * static_cast<double>(payload.size() - ivol::kPredictedHeaderSize) /
           (static_cast<double>(d[0]) * d[1] * d[2]);
  };
  for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16})
    for (const BrickDims& d : {BrickDims{32, 32, 32}, BrickDims{4, 4, 4}, BrickDims{1, 1, 1}}) {
      const auto v = smooth_brick(d, e, 21);
      const auto planes = encode_with(v, d, e, Entropy::ZstdPlanes);
      const auto tokens = encode_with(v, d, e, Entropy::Tokens);
      const auto smaller = encode_with(v, d, e, Entropy::Smaller);
      EXPECT_EQ(planes[3], 1);
      EXPECT_EQ(tokens[3], 2) << d[0];  // these bricks are within codec 3's limit either way
      if (bits_per_voxel(tokens, d) >= 1.0 && std::size_t{d[0]} * d[1] * d[2] >= 4096)
        EXPECT_EQ(smaller, tokens) << d[0];
      else
        EXPECT_EQ(smaller.size(), std::min(planes.size(), tokens.size())) << d[0];
      for (const auto* p : {&planes, &tokens, &smaller}) {
        EXPECT_EQ(decode(*p, d), v);
        EXPECT_EQ(reference_decode(*p, d), v);
      }
    }
  // A brick of one value with a repeating line of steps: the residuals
  // repeat, tokens cost a fraction of a bit a voxel, and zstd's matches win.
  const BrickDims d{32, 32, 32};
  std::vector<std::uint16_t> flat(std::size_t{32} * 32 * 32, 1000);
  for (std::size_t i = 0; i < flat.size(); i += 97) flat[i] = static_cast<std::uint16_t>(1000 + 40 * (i % 7));
  const auto tokens = encode_with(flat, d, ValueEncoding::UInt16, Entropy::Tokens);
  const auto planes = encode_with(flat, d, ValueEncoding::UInt16, Entropy::ZstdPlanes);
  ASSERT_LT(bits_per_voxel(tokens, d), 1.0);
  ASSERT_LT(planes.size(), tokens.size());
  const auto smaller = encode_with(flat, d, ValueEncoding::UInt16, Entropy::Smaller);
  EXPECT_EQ(smaller, planes);
  EXPECT_EQ(decode(smaller, d), flat);
  // On a smooth CT-like brick the tokens win.
  const auto v = smooth_brick(d, ValueEncoding::UInt16, 4);
  EXPECT_LT(encode_with(v, d, ValueEncoding::UInt16, Entropy::Tokens).size(),
            encode_with(v, d, ValueEncoding::UInt16, Entropy::ZstdPlanes).size());
  EXPECT_EQ(encode_with(v, d, ValueEncoding::UInt16, Entropy::Smaller),
            encode_with(v, d, ValueEncoding::UInt16, Entropy::Tokens));
}

// Auto, the writers' default: coder 3 (header byte 3 = 3) at zstd levels up
// to 3, whatever the brick's size; above, Smaller's choice (coder 2 in a
// 32³ brick, coder 3 in a 64³ one).
TEST(PredictedCodec, AutoTakesCoderThreeAtTheDefaultLevels) {
  for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16})
    for (const BrickDims& d : {BrickDims{32, 32, 32}, BrickDims{64, 64, 64}}) {
      const auto v = smooth_brick(d, e, 8);
      const bool large = d[0] == 64;
      for (const int level : {1, 3, 4, 19}) {
        ivol::PredictedOptions o;
        o.zstd_level = level;
        ASSERT_EQ(o.entropy, Entropy::Auto);  // the default
        const auto payload = ivol::encode_predicted(v.data(), d, e, o);
        EXPECT_EQ(payload[3], level <= 3 || large ? 3 : 2) << d[0] << " at level " << level;
        o.entropy = Entropy::Smaller;
        EXPECT_EQ(ivol::encode_predicted(v.data(), d, e, o)[3], large ? 3 : 2) << d[0] << " at level " << level;
        EXPECT_EQ(decode(payload, d), v);
        EXPECT_EQ(reference_decode(payload, d), v);
      }
    }
}

// Residuals of every bit length (tokens 0 .. 31) and context tables made
// again hundreds of times: a smooth brick with spikes of 0 and 65535, and
// a brick of 64 x 32 x 32 (far past 128 tokens a context).
TEST(PredictedCodec, TokensOfEverySizeAndLongBricksRoundTrip) {
  std::mt19937 rng(5);
  for (const BrickDims& d : {BrickDims{16, 16, 16}, BrickDims{64, 32, 32}, BrickDims{31, 7, 9}, BrickDims{2, 3, 1}}) {
    auto v = smooth_brick(d, ValueEncoding::UInt16, 8);
    for (std::size_t i = 0; i < v.size(); ++i)
      if (rng() % 23 == 0) v[i] = static_cast<std::uint16_t>(rng() % 2 ? 65535 : rng() >> (rng() % 16));
    const auto p = encode_with(v, d, ValueEncoding::UInt16, Entropy::Tokens);
    EXPECT_EQ(p[3], 2);
    EXPECT_EQ(decode(p, d), v) << d[0] << "x" << d[1] << "x" << d[2];
    EXPECT_EQ(reference_decode(p, d), v);
  }
  // Random bits of every shape: where the tokens exceed codec 3's limit the
  // encoder falls back to coder 1, and either way the bits come back.
  for (const BrickDims& d : {BrickDims{1, 1, 1}, BrickDims{5, 3, 7}, BrickDims{32, 32, 5}}) {
    std::vector<std::uint16_t> v(count(d));
    for (auto& x : v) x = static_cast<std::uint16_t>(rng());
    const auto p = encode_with(v, d, ValueEncoding::Binary16, Entropy::Tokens);
    EXPECT_LE(p.size(), ivol::predicted_payload_bound(v.size()));
    EXPECT_EQ(decode(p, d), v);
    EXPECT_EQ(reference_decode(p, d), v);
  }
}

// Every 16-bit residual through entropy coder 2 itself, in raster order and
// shuffled (the encoder finds tokens by a float's exponent, the decoder
// reads them from tables: both against the spec's plain decoder), and the
// coded bytes cut at every length: the decoder's fast paths read ahead of
// what they use, and must neither read past the payload (the ASan suite
// runs this) nor accept a cut.
TEST(PredictedCodec, EverySixteenBitResidualThroughTheTokensCoder) {
  const BrickDims d{64, 32, 32};
  std::vector<std::uint16_t> z(count(d));
  for (std::size_t i = 0; i < z.size(); ++i) z[i] = static_cast<std::uint16_t>(i);
  std::vector<std::uint16_t> shuffled = z;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(11));
  for (const auto* residuals : {&z, &shuffled}) {
    std::vector<std::uint8_t> coded;
    ASSERT_TRUE(ivol::detail::encode_residual_tokens(residuals->data(), d, 4 * z.size(), coded));
    std::vector<std::uint16_t> decoded(z.size());
    ivol::detail::decode_residual_tokens(coded.data(), coded.size(), d, decoded.data());
    const auto planes = spec_token_planes(coded.data(), coded.size(), d);
    std::size_t wrong = 0, unlike_spec = 0;
    for (std::size_t i = 0; i < z.size(); ++i) {
      wrong += decoded[i] != (*residuals)[i];
      unlike_spec += decoded[i] != (planes[i] | planes[z.size() + i] << 8);
    }
    EXPECT_EQ(wrong, 0u);
    EXPECT_EQ(unlike_spec, 0u);
  }
  const BrickDims small{9, 5, 4};
  std::vector<std::uint16_t> r(count(small));
  std::mt19937 rng(3);
  for (auto& v : r) v = static_cast<std::uint16_t>(rng() >> (rng() % 32));
  std::vector<std::uint8_t> coded;
  ASSERT_TRUE(ivol::detail::encode_residual_tokens(r.data(), small, 4 * r.size(), coded));
  std::vector<std::uint16_t> decoded(r.size());
  for (std::size_t cut = 0; cut < coded.size(); ++cut) {
    const std::vector<std::uint8_t> part(coded.begin(), coded.begin() + static_cast<std::ptrdiff_t>(cut));
    EXPECT_THROW(ivol::detail::decode_residual_tokens(part.data(), part.size(), small, decoded.data()), ivol::Error)
        << cut;
  }
}

TEST(PredictedCodec, HostileTokenPayloadsAreRefused) {
  const BrickDims d{8, 8, 8};
  const auto v = smooth_brick(d, ValueEncoding::UInt16, 5);
  const auto good = encode_with(v, d, ValueEncoding::UInt16, Entropy::Tokens);
  ASSERT_EQ(good[3], 2);
  const std::uint32_t R = le32(good.data() + 24);
  const std::size_t bits_at = 28 + R;
  ASSERT_LT(bits_at, good.size());  // a smooth brick has bits below its tokens
  using C = ivol::ErrorClass;
  auto with_length = [&](std::uint32_t r) {
    auto p = good;
    for (int k = 0; k < 4; ++k) p[24 + k] = static_cast<std::uint8_t>(r >> (8 * k));
    return p;
  };
  expect_refused(std::vector<std::uint8_t>(good.begin(), good.begin() + 27), d, C::Malformed, "no stream length");
  expect_refused(with_length(7), d, C::Malformed, "rANS stream's length 7");
  expect_refused(with_length(static_cast<std::uint32_t>(good.size() - 27)), d, C::Malformed, "rANS stream's length");
  auto p = good;
  p[28 + 3] = 0;  // X_0 below 2^23
  expect_refused(p, d, C::Malformed, "initial rANS state");
  p = good;
  p[28 + 7] |= 0x80;  // X_1 at 2^31 or more: no encoder's state
  expect_refused(p, d, C::Malformed, "initial rANS state");
  // One stream byte more or less: the states cannot end at 2^23, or the
  // stream runs out or is left over.
  p = good;
  p.insert(p.begin() + static_cast<std::ptrdiff_t>(bits_at), 0x5A);
  for (int k = 0; k < 4; ++k) p[24 + k] = static_cast<std::uint8_t>((R + 1) >> (8 * k));
  expect_refused(p, d, C::Malformed, "rANS");
  p = good;
  p.erase(p.begin() + static_cast<std::ptrdiff_t>(bits_at) - 1);
  for (int k = 0; k < 4; ++k) p[24 + k] = static_cast<std::uint8_t>((R - 1) >> (8 * k));
  expect_refused(p, d, C::Malformed, "rANS");
  p = good, p.push_back(0);
  expect_refused(p, d, C::Malformed, "left after the bits below");
  p = std::vector<std::uint8_t>(good.begin(), good.end() - 1);
  expect_refused(p, d, C::Malformed, "bits below the tokens end");
  // A set bit above the last residual's bits (E of them, from the residuals).
  const auto planes = spec_token_planes(good.data() + 24, good.size() - 24, d);
  std::size_t E = 0;
  for (std::size_t i = 0; i < count(d); ++i) {
    const unsigned z = planes[i] | planes[count(d) + i] << 8;
    const unsigned b = z ? 32 - static_cast<unsigned>(__builtin_clz(z)) : 0;
    E += b > 2 ? b - 2 : 0;
  }
  ASSERT_EQ(good.size() - bits_at, (E + 7) / 8);
  ASSERT_NE(E % 8, 0u) << "choose a brick whose bits do not fill their last byte";
  p = good, p.back() = static_cast<std::uint8_t>(p.back() | 0x80);
  expect_refused(p, d, C::Malformed, "padding bits");
  // Damage anywhere: only ivol::Error or a brick of other values, never a crash.
  std::mt19937 rng(2);
  for (int trial = 0; trial < 3000; ++trial) {
    p = good;
    const int flips = 1 + rng() % 4;
    for (int k = 0; k < flips; ++k) p[24 + rng() % (p.size() - 24)] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    if (rng() % 3 == 0) p.resize(24 + rng() % (p.size() - 24));
    try {
      decode(p, d);
    } catch (const ivol::Error& e) {
      EXPECT_EQ(e.error_class(), C::Malformed) << e.what();
    }
  }
}

}  // namespace
