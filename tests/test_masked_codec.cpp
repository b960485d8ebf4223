// Codec 4, masked 16-bit (spec §7.3): exact round trips of any bits (a
// background of −0 or a NaN included), a decoder written here from the spec
// as the reference, payloads built here from the spec decoded by libformat,
// and hostile payloads refused with clear errors.
#include <gtest/gtest.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <string>

#include "ivol/error.hpp"
#include "ivol/geometry.hpp"
#include "ivol/masked_codec.hpp"

namespace {

using Bytes = std::vector<std::uint8_t>;

// The spec's decoder (§7.3), value by value.
std::vector<std::uint16_t> reference_decode(const Bytes& payload, std::size_t n) {
  const std::uint16_t background = static_cast<std::uint16_t>(payload[0] | payload[1] << 8);
  if (payload[2] == 0) return std::vector<std::uint16_t>(n, background);
  const unsigned long long size = ZSTD_getFrameContentSize(payload.data() + 4, payload.size() - 4);
  Bytes content(size);
  EXPECT_EQ(ZSTD_decompress(content.data(), content.size(), payload.data() + 4, payload.size() - 4), size);
  const std::size_t m = (n + 7) / 8;
  std::size_t k = 0;
  for (std::size_t i = 0; i < n; ++i) k += ((content[i / 8] >> (i % 8)) & 1) == 0;
  EXPECT_EQ(content.size(), m + 2 * k);
  std::vector<std::uint16_t> out;
  for (std::size_t i = 0, j = 0; i < n; ++i)
    if ((content[i / 8] >> (i % 8)) & 1)
      out.push_back(background);
    else
      out.push_back(static_cast<std::uint16_t>(content[m + j] + 256 * content[m + k + j])), ++j;
  return out;
}

// A payload built from the spec: header, then a frame of `content`.
Bytes payload_of(std::uint16_t background, std::uint8_t form, const Bytes& content, std::uint8_t reserved = 0) {
  Bytes p{static_cast<std::uint8_t>(background), static_cast<std::uint8_t>(background >> 8), form, reserved};
  if (content.empty() && form == 0) return p;
  Bytes frame(ZSTD_compressBound(content.size()));
  frame.resize(ZSTD_compress(frame.data(), frame.size(), content.data(), content.size(), 3));
  p.insert(p.end(), frame.begin(), frame.end());
  return p;
}

std::vector<std::uint16_t> decode(const Bytes& payload, std::size_t n) {
  std::vector<std::uint16_t> out(n, 0x1234);
  ivol::decode_masked(payload.data(), payload.size(), n, out.data());
  return out;
}

// A brick where `share` of the values are `background`, the rest random bits
// with the special binary16 patterns among them.
std::vector<std::uint16_t> brick(std::size_t n, std::uint16_t background, double share, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const std::uint16_t special[] = {0x8000, 0x0000, 0x7E01, 0xFC00, 0x7C00, 0x0001};
  std::vector<std::uint16_t> v(n);
  for (std::size_t i = 0; i < n; ++i)
    v[i] = u(rng) < share ? background : i % 11 == 0 ? special[i % 6] : static_cast<std::uint16_t>(rng());
  return v;
}

TEST(MaskedCodec, EveryShareOfBackgroundRoundTripsExactly) {
  for (std::size_t n : {1u, 7u, 8u, 9u, 64u, 4096u, 32768u})
    for (std::uint16_t background : {std::uint16_t{0x8000}, std::uint16_t{0x7E01}, std::uint16_t{0}})
      for (double share : {0.0, 0.1, 0.5, 0.97, 1.0}) {
        const auto v = brick(n, background, share, static_cast<unsigned>(n + background));
        const Bytes p = ivol::encode_masked(v.data(), v.size(), background, 3);
        SCOPED_TRACE(std::to_string(n) + " " + std::to_string(background) + " " + std::to_string(share));
        ASSERT_LE(p.size(), ivol::masked_payload_bound(n));
        EXPECT_EQ(reference_decode(p, n), v);
        EXPECT_EQ(decode(p, n), v);
        const bool all_background = std::count(v.begin(), v.end(), background) == static_cast<long>(n);
        EXPECT_EQ(p[2], all_background ? 0 : 1);
        if (all_background) EXPECT_EQ(p.size(), 4u);  // a constant brick: the header alone
      }
}

TEST(MaskedCodec, DecodesPayloadsBuiltFromTheSpec) {
  // 10 values, background 0x8000 (−0) at 0, 3, 4, 9: mask bits 0, 3, 4 of
  // byte 0 and bit 1 of byte 1; the others 1 .. 6 as low bytes then high.
  const std::vector<std::uint16_t> want{0x8000, 0x0102, 0x0304, 0x8000, 0x8000, 0x0506, 0x0708, 0x090A, 0x0B0C, 0x8000};
  const Bytes content{0x19, 0x02, 0x02, 0x04, 0x06, 0x08, 0x0A, 0x0C, 0x01, 0x03, 0x05, 0x07, 0x09, 0x0B};
  EXPECT_EQ(decode(payload_of(0x8000, 1, content), 10), want);
  EXPECT_EQ(decode(payload_of(0x7E01, 0, {}), 5), std::vector<std::uint16_t>(5, 0x7E01));
  // Form 1 with every bit set: the frame holds the mask alone.
  EXPECT_EQ(decode(payload_of(42, 1, {0xFF, 0x03}), 10), std::vector<std::uint16_t>(10, 42));
}

TEST(MaskedCodec, RefusesPayloadsThatBreakTheSpec) {
  const Bytes ok_content{0xFE, 0x01, 0x00};  // 8 values: value 0 is 0x0001, the rest the background
  struct Case {
    const char* name;
    Bytes payload;
    const char* message;
  };
  Bytes extra = payload_of(7, 1, ok_content);
  extra.push_back(0);
  const Case cases[] = {
      {"short", {7, 0, 0}, "shorter than the codec header"},
      {"reserved", payload_of(7, 1, ok_content, 1), "reserved byte 3"},
      {"form 2", payload_of(7, 2, ok_content), "form 2"},
      {"constant with bytes after", payload_of(7, 0, ok_content), "exactly 4 bytes"},
      {"not a frame", {7, 0, 1, 0, 1, 2, 3, 4, 5}, "not a zstd frame"},
      {"content below the mask", payload_of(7, 1, {}), "not the 1-byte mask"},
      {"odd content", payload_of(7, 1, {0xFE, 1, 0, 0}), "not the 1-byte mask"},
      {"content above every value", payload_of(7, 1, Bytes(1 + 16 + 2, 0)), "not the 1-byte mask"},
      {"mask and values disagree", payload_of(7, 1, {0xFC, 1, 0}), "mask leaves 2 values"},
      {"trailing byte", extra, "not exactly one complete zstd frame"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    try {
      decode(c.payload, 8);
      ADD_FAILURE() << "accepted";
    } catch (const ivol::Error& e) {
      EXPECT_EQ(e.error_class(), ivol::ErrorClass::Malformed);
      EXPECT_NE(std::string(e.what()).find(c.message), std::string::npos) << e.what();
    }
  }
  // Padding bits past the last value (n = 6: bits 6 and 7 of the one byte).
  try {
    decode(payload_of(7, 1, {0xFF}), 6);
    ADD_FAILURE() << "accepted";
  } catch (const ivol::Error& e) {
    EXPECT_NE(std::string(e.what()).find("past the last value"), std::string::npos) << e.what();
  }
}

// The frame holds the mask, the low bytes and the high bytes each in zstd
// blocks of their own (entropy tables of their own): one frame with its
// content size, and smaller than the same content compressed in one run
// when the low bytes are noise and the high bytes smooth (CT values).
TEST(MaskedCodec, EachPartEndsAZstdBlock) {
  std::mt19937 rng(7);
  std::vector<std::uint16_t> v(32768, 0x8000);
  std::size_t others = 0;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (i % 3 != 0) v[i] = static_cast<std::uint16_t>(0x3800 + (i >> 12) * 256 + rng() % 256), ++others;
  const Bytes p = ivol::encode_masked(v.data(), v.size(), 0x8000, 3);
  const std::uint8_t* frame = p.data() + 4;
  const std::size_t size = p.size() - 4;
  const std::size_t m = v.size() / 8;
  ASSERT_EQ(ZSTD_getFrameContentSize(frame, size), m + 2 * others);
  ASSERT_EQ(ZSTD_findFrameCompressedSize(frame, size), size);
  // Count the zstd blocks (RFC 8878 §3.1.1.2): the frame header, then
  // 3-byte block headers.
  std::size_t at = 4;
  const std::uint8_t descriptor = frame[at++];
  const unsigned fcs_flag = descriptor >> 6, single = (descriptor >> 5) & 1, dict_flag = descriptor & 3;
  at += single ? 0 : 1;
  at += dict_flag == 0 ? 0 : dict_flag == 1 ? 1 : dict_flag == 2 ? 2 : 4;
  at += fcs_flag == 0 ? (single ? 1 : 0) : fcs_flag == 1 ? 2 : fcs_flag == 2 ? 4 : 8;
  int blocks = 0;
  for (bool last = false; !last; ++blocks) {
    const std::uint32_t h = frame[at] | frame[at + 1] << 8 | frame[at + 2] << 16;
    last = h & 1;
    at += 3 + ((h >> 1 & 3) == 1 ? 1 : h >> 3);
  }
  EXPECT_GE(blocks, 3);
  Bytes content(m, 0);
  Bytes lo, hi;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (v[i] == 0x8000)
      content[i / 8] = static_cast<std::uint8_t>(content[i / 8] | 1u << (i % 8));
    else
      lo.push_back(static_cast<std::uint8_t>(v[i])), hi.push_back(static_cast<std::uint8_t>(v[i] >> 8));
  content.insert(content.end(), lo.begin(), lo.end());
  content.insert(content.end(), hi.begin(), hi.end());
  Bytes one_run(ZSTD_compressBound(content.size()));
  one_run.resize(ZSTD_compress(one_run.data(), one_run.size(), content.data(), content.size(), 3));
  EXPECT_LT(size, one_run.size());
  EXPECT_EQ(decode(p, v.size()), v);
}

TEST(MaskedCodec, MostCommonValueAgainstACountedMap) {
  std::mt19937 rng(3);
  for (int t = 0; t < 40; ++t) {
    std::vector<std::uint16_t> v(1 + rng() % 3000);
    for (auto& x : v) x = static_cast<std::uint16_t>(rng() % (2 + t % 20 * 7));
    // From the 20th on, in runs of 1 to 60 (as air and flat material come):
    // the function counts runs at once.
    for (std::size_t i = 0; t >= 20 && i < v.size();) {
      const std::size_t run = 1 + rng() % 60;
      for (std::size_t k = 1; k < run && i + k < v.size(); ++k) v[i + k] = v[i];
      i += run;
    }
    std::map<std::uint16_t, std::size_t> counts;
    for (auto x : v) ++counts[x];
    std::pair<std::uint16_t, std::size_t> best{0, 0};
    for (const auto& [value, c] : counts)
      if (c > best.second) best = {value, c};  // the smallest value wins a tie (map order)
    const ivol::CommonValue got = ivol::most_common_value(v.data(), v.size());
    EXPECT_EQ(got.value, best.first);
    EXPECT_EQ(got.count, best.second);
  }
}

// likely_background finds the background from a sample of every 127th
// voxel: for bricks of 32³, 64³ and 32 x 32 x 20 (a volume's edge) whose
// background fills an eighth of them, as a slab along each axis, a corner
// box, the part of a ball and scattered voxels, it names that background
// with the count most_common_value gives; in noise it names nothing, or a
// value with its exact count.
TEST(MaskedCodec, LikelyBackgroundFindsAnEighthFromItsSample) {
  std::mt19937 rng(7);
  constexpr std::uint16_t kBackground = 0x3C00;
  const ivol::Dims sizes[] = {{32, 32, 32}, {64, 64, 64}, {32, 32, 20}};
  for (const ivol::Dims& d : sizes) {
    const std::size_t n = std::size_t{d[0]} * d[1] * d[2];
    auto noise = [&] {
      std::vector<std::uint16_t> v(n);
      for (auto& x : v) x = static_cast<std::uint16_t>(0x4000 + rng() % 16384);
      return v;
    };
    using Inside = std::function<bool(std::uint32_t, std::uint32_t, std::uint32_t)>;
    const std::uint32_t slab_x = (d[0] + 7) / 8, slab_y = (d[1] + 7) / 8, slab_z = (d[2] + 7) / 8;
    const double radius = std::cbrt(6.0 * static_cast<double>(n) / 3.14159265) * 1.01;  // an octant of a ball
    const std::pair<const char*, Inside> shapes[] = {
        {"slab along x", [&](auto x, auto, auto) { return x >= d[0] - slab_x; }},
        {"slab along y", [&](auto, auto y, auto) { return y < slab_y; }},
        {"slab along z", [&](auto, auto, auto z) { return z >= d[2] - slab_z; }},
        {"corner box", [&](auto x, auto y, auto z) { return x < d[0] / 2 && y < d[1] / 2 && z < (d[2] + 1) / 2; }},
        {"ball", [&](auto x, auto y, auto z) { return std::hypot(x + 0.5, y + 0.5, z + 0.5) < radius; }},
        {"scattered", [&](auto, auto, auto) { return rng() % 7 == 0; }},
    };
    for (const auto& [name, inside] : shapes) {
      SCOPED_TRACE(std::string(name) + ", " + std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" +
                   std::to_string(d[2]));
      std::vector<std::uint16_t> v = noise();
      std::size_t i = 0;
      for (std::uint32_t z = 0; z < d[2]; ++z)
        for (std::uint32_t y = 0; y < d[1]; ++y)
          for (std::uint32_t x = 0; x < d[0]; ++x, ++i)
            if (inside(x, y, z)) v[i] = kBackground;
      const ivol::CommonValue all = ivol::most_common_value(v.data(), n);
      ASSERT_EQ(all.value, kBackground);
      ASSERT_GE(8 * all.count, n) << "the shape fills less than an eighth";
      const ivol::CommonValue sampled = ivol::likely_background(v.data(), n);
      EXPECT_EQ(sampled.value, kBackground);
      EXPECT_EQ(sampled.count, all.count);
    }
    const std::vector<std::uint16_t> v = noise();
    const ivol::CommonValue sampled = ivol::likely_background(v.data(), n);
    if (sampled.count != 0)
      EXPECT_EQ(sampled.count, static_cast<std::size_t>(std::count(v.begin(), v.end(), sampled.value)));
    EXPECT_LT(8 * sampled.count, n);
  }
}

}  // namespace
