// Codec 6, top byte in context (spec §7.4): exact round trips of any bits in
// bricks of any shape, both widths and so both modes; the spec's limits;
// hostile payloads refused with clear errors and never read out of bounds;
// the bricked writer choosing it where noise dominates, with every bit back.
// The payloads' bytes are checked against an encoder written from the spec
// alone by the conformance vectors (format-spec/vectors, make_vectors.py),
// which test_conformance_vectors and the reference reader decode.
#include <gtest/gtest.h>
#include <zstd.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "ivol/binary16.hpp"
#include "ivol/bricked_writer.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/top_byte_codec.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;
using Bytes = std::vector<std::uint8_t>;

std::size_t count_of(const BrickDims& d) { return std::size_t{d[0]} * d[1] * d[2]; }

// A CT-like field: a ball of material (0.05) in air (0), with noise as a
// filtered backprojection leaves it: high-pass (neighbours anticorrelated,
// from the ramp filter) and of a strength that varies across the volume
// (streaks, the part's shadow), so that in the air the sign flips from voxel
// to voxel and the magnitudes come in regions. Voxel i of extent d.
std::vector<float> ct_field(const BrickDims& d, unsigned seed, float sigma) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const std::size_t n = count_of(d);
  std::vector<float> white(n), out(n);
  for (auto& v : white) v = noise(rng);
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        float c = white[i];
        if (x) c -= 0.4f * white[i - 1];
        if (y) c -= 0.3f * white[i - d[0]];
        const float strength =
            sigma * (0.2f + 1.8f * static_cast<float>(
                                       std::pow(std::sin(0.11 * x + 0.07 * y) * std::cos(0.05 * z + 0.13 * y), 2)));
        const double r = std::hypot(x - d[0] / 2.0, y - d[1] / 2.0, z - d[2] / 2.0);
        out[i] = (r < d[0] / 4.0 ? 0.05f : 0.0f) + strength * c;
      }
  return out;
}

// The field as binary16, with the special patterns sprinkled in.
Bytes noisy_binary16(const BrickDims& d, unsigned seed, float sigma = 0.01f) {
  const std::vector<float> f = ct_field(d, seed, sigma);
  Bytes out(2 * f.size());
  const std::uint16_t special[] = {0x8000, 0x7E01, 0xFC00, 0x7C00, 0x0001, 0x7BFF};
  for (std::size_t i = 0; i < f.size(); ++i) {
    const std::uint16_t h = i % 53 == 7 ? special[(i / 53) % 6] : float_to_binary16(f[i]);
    out[2 * i] = static_cast<std::uint8_t>(h);
    out[2 * i + 1] = static_cast<std::uint8_t>(h >> 8);
  }
  return out;
}

Bytes noisy_float32(const BrickDims& d, unsigned seed, float sigma = 0.01f) {
  const std::vector<float> f = ct_field(d, seed, sigma);
  Bytes out(4 * f.size());
  const std::uint32_t special[] = {0x80000000u, 0x7FC01234u, 0xFF800000u, 0x00000001u};
  for (std::size_t i = 0; i < f.size(); ++i) {
    std::uint32_t bits;
    std::memcpy(&bits, &f[i], 4);
    if (i % 41 == 3) bits = special[(i / 41) % 4];
    for (int k = 0; k < 4; ++k) out[4 * i + k] = static_cast<std::uint8_t>(bits >> (8 * k));
  }
  return out;
}

// zstd over the values' byte planes, one frame (codec 2's way), for scale.
std::size_t zstd_planes(const Bytes& values, unsigned w) {
  const std::size_t n = values.size() / w;
  Bytes planes(values.size());
  for (std::size_t i = 0; i < n; ++i)
    for (unsigned p = 0; p < w; ++p) planes[p * n + i] = values[i * w + p];
  Bytes frame(ZSTD_compressBound(planes.size()));
  return ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), 3);
}

Bytes random_bytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  Bytes out(n);
  for (auto& b : out) b = static_cast<std::uint8_t>(rng());
  return out;
}

Bytes decode(const Bytes& payload, const BrickDims& d, unsigned w) {
  Bytes out(count_of(d) * w, 0xA5);
  decode_top_byte(payload.data(), payload.size(), d, w, out.data());
  return out;
}

TEST(TopByteCodec, AnyBitsRoundTripInBricksOfAnyShape) {
  const BrickDims shapes[] = {{1, 1, 1}, {5, 3, 4}, {7, 1, 1}, {1, 9, 2}, {16, 16, 16}, {32, 32, 32}, {31, 17, 3}};
  unsigned seed = 1;
  for (const BrickDims& d : shapes)
    for (unsigned w : {2u, 4u}) {
      const std::size_t n = count_of(d);
      for (const Bytes& values :
           {w == 2 ? noisy_binary16(d, seed) : noisy_float32(d, seed), random_bytes(n * w, seed), Bytes(n * w, 0x3C)}) {
        ++seed;
        const Bytes payload = encode_top_byte(values.data(), d, w, SIZE_MAX);
        if (payload.empty()) continue;  // larger than the values stored: another codec's
        ASSERT_LE(payload.size(), top_byte_payload_bound(n, w));
        EXPECT_EQ(payload[2], w == 4 ? 1 : 0) << "the library's mode: 1 for 4-byte values";
        EXPECT_EQ(decode(payload, d, w), values) << d[0] << "x" << d[1] << "x" << d[2] << " w " << w;
      }
    }
}

// Noise is where the codec pays: on the CT-like field it is smaller than
// zstd over the byte planes, the codec the writer would otherwise keep.
TEST(TopByteCodec, CorrelatedNoiseCostsLessThanZstdOverBytePlanes) {
  const BrickDims d{32, 32, 32};
  const Bytes b16 = noisy_binary16(d, 5);
  const Bytes p16 = encode_top_byte(b16.data(), d, 2, SIZE_MAX);
  ASSERT_FALSE(p16.empty());
  EXPECT_LT(p16.size(), zstd_planes(b16, 2));
  const Bytes f32 = noisy_float32(d, 6);
  const Bytes p32 = encode_top_byte(f32.data(), d, 4, SIZE_MAX);
  ASSERT_FALSE(p32.empty());
  EXPECT_LT(p32.size(), zstd_planes(f32, 4));
}

TEST(TopByteCodec, GivesUpWhenItCannotBeSmaller) {
  const BrickDims d{16, 16, 16};
  const std::size_t n = count_of(d);
  const Bytes values = noisy_binary16(d, 9);
  const Bytes full = encode_top_byte(values.data(), d, 2, SIZE_MAX);
  ASSERT_FALSE(full.empty());
  EXPECT_TRUE(encode_top_byte(values.data(), d, 2, full.size()).empty());
  EXPECT_EQ(encode_top_byte(values.data(), d, 2, full.size() + 1), full);
  // Random bits do not fit the spec's limit of the values and 12 bytes.
  const Bytes random = random_bytes(2 * n, 10);
  const Bytes r = encode_top_byte(random.data(), d, 2, SIZE_MAX);
  if (!r.empty()) EXPECT_LE(r.size(), top_byte_payload_bound(n, 2));
}

void expect_malformed(const Bytes& payload, const BrickDims& d, unsigned w, const std::string& says) {
  try {
    decode(payload, d, w);
    ADD_FAILURE() << "accepted; expected: " << says;
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::Malformed) << e.what();
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
  }
}

TEST(TopByteCodec, HostilePayloadsAreRefusedWithTheRuleTheyBreak) {
  const BrickDims d{8, 8, 5};  // n = 320
  const std::size_t n = count_of(d);
  const Bytes f32 = noisy_float32(d, 11);
  const Bytes good = encode_top_byte(f32.data(), d, 4, SIZE_MAX);
  ASSERT_FALSE(good.empty());
  auto with = [&](std::size_t at, std::uint8_t v) {
    Bytes p = good;
    p[at] = v;
    return p;
  };
  expect_malformed(Bytes(good.begin(), good.begin() + 6), d, 4, "shorter than the codec header");
  expect_malformed(with(0, 128), d, 4, "centre 128");
  expect_malformed(with(1, 0), d, 4, "step is 0");
  expect_malformed(with(2, 2), d, 4, "mode 2");
  expect_malformed(with(3, 1), d, 4, "reserved byte 3");
  Bytes longer = good;
  longer.push_back(0);
  expect_malformed(longer, d, 4, "the payload holds");
  expect_malformed(Bytes(good.begin(), good.end() - 1), d, 4, "the payload holds");
  Bytes r3 = good;
  r3[4] = 3, r3[5] = r3[6] = r3[7] = 0;
  expect_malformed(r3, d, 4, "rANS stream's length 3");
  Bytes state = good;
  state[11] = 0x80;  // the initial state ≥ 2^31
  expect_malformed(state, d, 4, "initial rANS state");
  // An odd brick in mode 1: its padding nibble must be 0.
  const BrickDims odd{9, 7, 5};
  const Bytes o = noisy_float32(odd, 12);
  Bytes padded = encode_top_byte(o.data(), odd, 4, SIZE_MAX);
  ASSERT_FALSE(padded.empty());
  padded.back() |= 0x10;
  expect_malformed(padded, odd, 4, "padding nibble");
  EXPECT_THROW(decode(good, d, 3), Error);
}

// Every byte of a payload changed, each alone, and every truncation: the
// decoder either decodes (rANS maps many streams to values) or refuses as
// malformed, and never reads past the payload (ASan in the sanitizer job).
TEST(TopByteCodec, EveryChangedByteAndEveryCutIsDecodedOrRefused) {
  const BrickDims d{6, 5, 4};
  for (unsigned w : {2u, 4u}) {
    const std::size_t n = count_of(d);
    const Bytes values = w == 2 ? noisy_binary16(d, 13) : noisy_float32(d, 14);
    const Bytes good = encode_top_byte(values.data(), d, w, SIZE_MAX);
    ASSERT_FALSE(good.empty());
    for (std::size_t at = 0; at < good.size(); ++at)
      for (std::uint8_t flip : {0x01, 0x80, 0xFF}) {
        Bytes p = good;
        p[at] ^= flip;
        // Copied to a buffer of exactly its size, so that ASan sees any read beyond it.
        std::vector<std::uint8_t> exact(p);
        try {
          decode(exact, d, w);
        } catch (const Error& e) {
          EXPECT_EQ(e.error_class(), ErrorClass::Malformed) << at << ": " << e.what();
        }
      }
    for (std::size_t size = 0; size < good.size(); ++size) {
      const Bytes cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(size));
      EXPECT_THROW(decode(cut, d, w), Error) << size;
    }
  }
}

// The writer tries codec 6 where noise dominates: a noisy binary16 volume
// holds codec 6 bricks at the default level (none when zstd's entropy
// coding is asked for, for its decoding speed), a noisy float32 one from
// level 13 (below, its bricks stay zstd's, which decode several times
// faster); every bit comes back, and check_file reads every block.
// A part whose values fall off into the air over many octaves (as the blur
// and scatter of a noise-free reconstruction leave them), with noise of
// 10^-5: the top bytes (sign and exponent) change smoothly across the brick.
Bytes smooth_float32(const BrickDims& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 1e-5f);
  Bytes out(4 * count_of(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const double r = std::hypot(x - 0.3 * d[0], y - 0.5 * d[1], z - 0.6 * d[2]);
        const float f = (r < 6 ? 0.05f : 0.05f * static_cast<float>(std::exp(-(r - 6) / 8))) + noise(rng);
        std::memcpy(&out[4 * i], &f, 4);
      }
  return out;
}

// The classes' step is the caller's when asked, as the header's S, and any
// step decodes. Where the top bytes change smoothly, the finer classes of
// steps 1 and 2 are smaller than the encoder's own choice (at least 4, made
// for noise): that is why the bricked writer tries them on float32 bricks.
TEST(TopByteCodec, TheClassesStepIsTheCallersWhenAsked) {
  const BrickDims d{32, 32, 32};
  const Bytes values = smooth_float32(d, 31);
  const Bytes chosen = encode_top_byte(values.data(), d, 4, SIZE_MAX);
  ASSERT_FALSE(chosen.empty());
  EXPECT_GE(chosen[1], 4) << "the encoder's own step is at least 4";
  for (const unsigned step : {1u, 2u, 7u, 255u, 1000u}) {
    const Bytes payload = encode_top_byte(values.data(), d, 4, SIZE_MAX, step);
    ASSERT_FALSE(payload.empty()) << "step " << step;
    EXPECT_EQ(payload[1], std::min(step, 255u));
    EXPECT_EQ(decode(payload, d, 4), values) << "step " << step;
  }
  EXPECT_LT(encode_top_byte(values.data(), d, 4, SIZE_MAX, 1).size(), chosen.size());
  EXPECT_LT(encode_top_byte(values.data(), d, 4, SIZE_MAX, 2).size(), chosen.size());
}

TEST(TopByteCodec, TheBrickedWriterChoosesItForNoiseAndEveryBitComesBack) {
  const Dims d{64, 64, 40};
  using Entropy = PredictedOptions::Entropy;
  struct Case {
    ValueEncoding encoding;
    int level;
    Entropy entropy;
    bool expect_codec6;
  };
  for (const Case c : {Case{ValueEncoding::Binary16, 3, Entropy::Smaller, true},
                       Case{ValueEncoding::Binary16, 3, Entropy::ZstdPlanes, false},
                       Case{ValueEncoding::Float32, 3, Entropy::Smaller, false},
                       Case{ValueEncoding::Float32, 13, Entropy::Smaller, true}}) {
    const ValueEncoding e = c.encoding;
    const std::size_t n = voxel_count(d);
    const BrickDims whole{d[0], d[1], d[2]};
    const Bytes bytes = e == ValueEncoding::Binary16 ? noisy_binary16(whole, 21) : noisy_float32(whole, 22);
    const std::string path = test::temp_path(e == ValueEncoding::Binary16 ? "c6_b16.ivol" : "c6_f32.ivol");
    BrickedOptions o;
    o.brick_log2 = 5;
    o.encoding = e;
    o.zstd_level = c.level;
    o.entropy = c.entropy;
    o.threads = 2;
    BrickedGridWriter writer(path, d, o);
    while (writer.next_layer_count() > 0) {
      const std::size_t at = std::size_t{writer.next_layer_first()} * d[0] * d[1];
      if (e == ValueEncoding::Float32) {
        std::vector<std::uint32_t> layer(std::size_t{d[0]} * d[1] * writer.next_layer_count());
        std::memcpy(layer.data(), bytes.data() + 4 * at, 4 * layer.size());
        writer.add_layer(layer.data());
      } else {
        std::vector<std::uint16_t> layer(std::size_t{d[0]} * d[1] * writer.next_layer_count());
        std::memcpy(layer.data(), bytes.data() + 2 * at, 2 * layer.size());
        writer.add_layer(layer.data());
      }
    }
    Metadata m;
    writer.finish(m);
    Reader r(path);
    std::size_t codec6 = 0, values_blocks = 0;
    for (const BlockInfo& b : r.info().blocks)
      if (b.stream == 3) ++values_blocks, codec6 += b.codec == 6;
    if (c.expect_codec6)
      EXPECT_GE(4 * codec6, values_blocks) << "codec 6 on " << codec6 << " of " << values_blocks << " bricks";
    else
      EXPECT_EQ(codec6, 0u) << "level " << c.level;
    EXPECT_EQ(r.read_box_bits(full_box(d), 0), bytes);
    EXPECT_TRUE(check_file(path).ok());
  }
}

}  // namespace
