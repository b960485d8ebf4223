// binary16 rounding against an oracle that picks the nearest of all 63 488
// finite binary16 values (ties to even), and exact decoding.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

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

// The oracle for rounding upward: the least of every binary16 number
// (infinities included, ordered as doubles) that is not below the float.
TEST(Binary16, UpwardIsTheLeastNumberNotBelow) {
  std::vector<double> all;
  for (std::uint32_t h = 0; h < 65536; ++h) {
    const double v = ivol::binary16_to_double(static_cast<std::uint16_t>(h));
    if (!std::isnan(v)) all.push_back(v);
  }
  std::sort(all.begin(), all.end());
  std::mt19937 rng(5);
  auto check = [&](float f) {
    const std::uint16_t up = ivol::float_to_binary16_upward(f);
    if (std::isnan(f)) {
      ASSERT_EQ(up, 0x7E00);
      return;
    }
    const auto least = std::lower_bound(all.begin(), all.end(), static_cast<double>(f));
    ASSERT_NE(least, all.end()) << f;
    ASSERT_EQ(ivol::binary16_to_double(up), *least) << f;
  };
  for (int n = 0; n < 2000000; ++n) {
    std::uint32_t bits = rng();
    float f;
    std::memcpy(&f, &bits, 4);
    check(f);
  }
  // Every binary16 number and its float neighbours on either side.
  for (std::uint32_t h = 0; h < 65536; ++h) {
    const float v = ivol::binary16_to_float(static_cast<std::uint16_t>(h));
    check(v);
    check(std::nextafter(v, INFINITY));
    check(std::nextafter(v, -INFINITY));
  }
  EXPECT_EQ(ivol::float_to_binary16_upward(65504.5F), 0x7C00);
  EXPECT_EQ(ivol::float_to_binary16_upward(-65600.0F), 0xFBFF);
  EXPECT_EQ(ivol::float_to_binary16_upward(-1e-30F), 0x8000);
  EXPECT_EQ(ivol::float_to_binary16_upward(1e-30F), 0x0001);
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
