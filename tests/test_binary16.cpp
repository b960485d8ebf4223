// binary16 rounding against an oracle that picks the nearest of all 63 488
// finite binary16 values (ties to even), and exact decoding.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "ivol/binary16.hpp"
#include "ivol/encoding.hpp"
#include "test_support.hpp"

namespace {

using ivol::ValueEncoding;
using ivol::test::reference_decode;
using ivol::test::reference_encode;

TEST(Binary16, DecodesEveryPatternExactly) {
  for (std::uint32_t b = 0; b < 0x10000; ++b) {
    const double expected = reference_decode(ValueEncoding::Binary16, b);
    const double got = ivol::binary16_to_double(static_cast<std::uint16_t>(b));
    if (std::isnan(expected))
      ASSERT_TRUE(std::isnan(got)) << b;
    else
      ASSERT_EQ(got, expected) << b;
  }
}

TEST(Binary16, RoundTripsEveryValue) {
  for (std::uint32_t b = 0; b < 0x10000; ++b) {
    const auto bits = static_cast<std::uint16_t>(b);
    const float f = ivol::binary16_to_float(bits);
    if (std::isnan(f)) {
      EXPECT_EQ(ivol::float_to_binary16(f), 0x7E00);
      continue;
    }
    ASSERT_EQ(ivol::float_to_binary16(f), bits) << b;
    ASSERT_EQ(ivol::double_to_binary16(f), bits) << b;
  }
}

TEST(Binary16, MidpointsRoundToEven) {
  // Every midpoint between neighbouring finite values, and one ulp (of the
  // double) either side of it.
  for (std::uint32_t b = 0; b < 0x7BFF; ++b) {
    const double lo = reference_decode(ValueEncoding::Binary16, b);
    const double hi = reference_decode(ValueEncoding::Binary16, b + 1);
    const double mid = (lo + hi) / 2;
    for (double x : {mid, std::nextafter(mid, 0.0), std::nextafter(mid, 1e9), -mid}) {
      const std::uint32_t expected = reference_encode(ValueEncoding::Binary16, x);
      ASSERT_EQ(ivol::double_to_binary16(x), expected) << x;
      const auto xf = static_cast<float>(x);
      if (static_cast<double>(xf) == x) ASSERT_EQ(ivol::float_to_binary16(xf), expected) << x;
    }
  }
}

TEST(Binary16, RandomFloatsMatchOracle) {
  std::mt19937 rng(3);
  for (int n = 0; n < 2000000; ++n) {
    std::uint32_t bits = rng();
    float f;
    std::memcpy(&f, &bits, 4);
    if (std::isnan(f)) continue;
    const std::uint32_t expected = reference_encode(ValueEncoding::Binary16, f);
    ASSERT_EQ(ivol::float_to_binary16(f), expected) << f;
    ASSERT_EQ(ivol::double_to_binary16(f), expected) << f;
  }
}

TEST(Binary16, OverflowAndSpecials) {
  EXPECT_EQ(ivol::double_to_binary16(65504.0), 0x7BFF);
  EXPECT_EQ(ivol::double_to_binary16(65519.99), 0x7BFF);
  EXPECT_EQ(ivol::double_to_binary16(65520.0), 0x7C00);
  EXPECT_EQ(ivol::double_to_binary16(-1e300), 0xFC00);
  EXPECT_EQ(ivol::float_to_binary16(INFINITY), 0x7C00);
  EXPECT_EQ(ivol::double_to_binary16(NAN), 0x7E00);
  EXPECT_EQ(ivol::double_to_binary16(-0.0), 0x8000);
  EXPECT_EQ(ivol::double_to_binary16(std::ldexp(1.0, -25)), 0x0000);  // tie to even: zero
  EXPECT_EQ(ivol::double_to_binary16(std::ldexp(3.0, -25)), 0x0002);  // tie to even: 2 units
}

TEST(Encoding, UInt16AndFloat32Rounding) {
  EXPECT_EQ(ivol::encode_value(ValueEncoding::UInt16, 2.5), 2u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::UInt16, 3.5), 4u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::UInt16, -7.0), 0u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::UInt16, 70000.0), 65535u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::Float32, 1e300), 0x7F800000u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::Float32, -1e300), 0xFF800000u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::Float32, NAN), 0x7FC00000u);
  EXPECT_EQ(ivol::encode_value(ValueEncoding::Float32, 3.4028234663852886e38), 0x7F7FFFFFu);
}

}  // namespace
