// Codec 5, byte planes a zstd frame each (spec §7): when the writer uses it
// (encode_block: zstd level 13 and up, planes of 4096 elements or more of 2
// or 4 bytes, format 1.3), that its blocks decode to the elements, and that
// every way its stored bytes can break §7's rules is refused with the class
// §13 gives. The frames here are made with zstd's own API, not ivol's.
#include <gtest/gtest.h>
#include <zstd.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "block_reader.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/writer.hpp"

namespace {

using namespace ivol;

// CT-like elements of `width` bytes: a smooth high part, noisy low bytes.
std::vector<std::uint8_t> elements(std::size_t n, std::size_t width, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> e(n * width);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t p = 0; p < width; ++p)
      e[i * width + p] = static_cast<std::uint8_t>(p + 1 == width ? 0x40 + i / 512 : p == 0 ? rng() : rng() % 16);
  return e;
}

std::vector<std::uint8_t> plane(const std::vector<std::uint8_t>& e, std::size_t width, std::size_t p) {
  const std::size_t n = e.size() / width;
  std::vector<std::uint8_t> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = e[i * width + p];
  return out;
}

std::vector<std::uint8_t> frame_of(const std::vector<std::uint8_t>& content, bool checksum = true,
                                   bool content_size = true) {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 3);
  ZSTD_CCtx_setParameter(c, ZSTD_c_checksumFlag, checksum ? 1 : 0);
  ZSTD_CCtx_setParameter(c, ZSTD_c_contentSizeFlag, content_size ? 1 : 0);
  std::vector<std::uint8_t> out(ZSTD_compressBound(content.size()));
  std::size_t size;
  if (content_size) {
    size = ZSTD_compress2(c, out.data(), out.size(), content.data(), content.size());
  } else {  // streamed without a pledged size: no Frame_Content_Size
    ZSTD_inBuffer in{content.data(), content.size(), 0};
    ZSTD_outBuffer o{out.data(), out.size(), 0};
    while (ZSTD_compressStream2(c, &o, &in, ZSTD_e_end) != 0) {
    }
    size = o.pos;
  }
  ZSTD_freeCCtx(c);
  out.resize(size);
  return out;
}

// The payload of codec 5 as §7 defines it, frame after frame.
std::vector<std::uint8_t> payload_of(const std::vector<std::uint8_t>& e, std::size_t width) {
  std::vector<std::uint8_t> out;
  for (std::size_t p = 0; p < width; ++p) {
    const auto f = frame_of(plane(e, width, p));
    out.insert(out.end(), f.begin(), f.end());
  }
  return out;
}

BlockInfo info_of(std::size_t n, const std::vector<std::uint8_t>& stored, std::uint8_t codec = 5) {
  BlockInfo b;
  b.stream = 3;
  b.codec = codec;
  b.element_count = static_cast<std::uint32_t>(n);
  b.stored_size = static_cast<std::uint32_t>(stored.size());
  b.crc = crc32c(stored.data(), stored.size());
  return b;
}

std::vector<std::uint8_t> decode(const std::vector<std::uint8_t>& stored, std::size_t n, std::size_t width) {
  std::vector<std::uint8_t> out(n * width);
  detail::decode_stored_into("t.ivol", info_of(n, stored), 0, width, false, std::nullopt, stored.data(), stored.size(),
                             out.data());
  return out;
}

TEST(PlaneFrames, TheWriterUsesCodec5FromLevel13ForPlanesOf4096ElementsOf2Or4Bytes) {
  struct Case {
    int level;
    std::size_t width, n;
    bool framed;
    Codec want;
  };
  const Case cases[] = {
      {12, 4, 4096, true, Codec::ZstdBytePlanes},   {13, 4, 4096, true, Codec::ZstdPlaneFrames},
      {19, 2, 32768, true, Codec::ZstdPlaneFrames}, {19, 4, 4095, true, Codec::ZstdBytePlanes},
      {19, 8, 8192, true, Codec::ZstdBytePlanes},   {19, 4, 8192, false, Codec::ZstdBytePlanes},
  };
  for (const Case& c : cases) {
    const auto e = elements(c.n, c.width, 3);
    WriteOptions o;
    o.zstd_level = c.level;
    o.framed_blocks = c.framed;
    const EncodedBlock block =
        encode_block(Stream::Values, 0, 0, static_cast<std::uint32_t>(c.n), c.width, e.data(), o);
    ASSERT_EQ(block.codec, c.want) << "level " << c.level << ", width " << c.width << ", n " << c.n;
    std::vector<std::uint8_t> out(e.size());
    detail::decode_stored_into("t.ivol", info_of(c.n, block.bytes, static_cast<std::uint8_t>(block.codec)), 0, c.width,
                               false, std::nullopt, block.bytes.data(), block.bytes.size(), out.data());
    EXPECT_EQ(out, e);
    if (block.codec != Codec::ZstdPlaneFrames) continue;
    // Exactly `width` frames, each of one plane, checked with zstd's own API.
    std::size_t at = 0;
    for (std::size_t p = 0; p < c.width; ++p) {
      const std::size_t size = ZSTD_findFrameCompressedSize(block.bytes.data() + at, block.bytes.size() - at);
      ASSERT_FALSE(ZSTD_isError(size));
      std::vector<std::uint8_t> content(c.n);
      ASSERT_EQ(ZSTD_decompress(content.data(), c.n, block.bytes.data() + at, size), c.n);
      EXPECT_EQ(content, plane(e, c.width, p)) << p;
      at += size;
    }
    EXPECT_EQ(at, block.bytes.size());
  }
}

TEST(PlaneFrames, PayloadsMadeByZstdDecode) {
  for (std::size_t width : {2u, 4u, 8u})
    for (std::size_t n : {1u, 2u, 7u, 5000u}) {
      const auto e = elements(n, width, static_cast<unsigned>(n + width));
      EXPECT_EQ(decode(payload_of(e, width), n, width), e) << width << " " << n;
    }
  // Frames without a checksum; plane 0, random bytes, is one raw zstd block.
  const auto e = elements(300, 4, 1);
  std::vector<std::uint8_t> p;
  for (std::size_t k = 0; k < 4; ++k) {
    const auto f = frame_of(plane(e, 4, k), /*checksum=*/k % 2 == 0);
    p.insert(p.end(), f.begin(), f.end());
  }
  EXPECT_EQ(decode(p, 300, 4), e);
}

void expect_refused(const std::vector<std::uint8_t>& stored, std::size_t n, std::size_t width, ErrorClass c,
                    const std::string& text) {
  try {
    decode(stored, n, width);
    FAIL() << "accepted: " << text;
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), c) << e.what();
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(PlaneFrames, PayloadsThatBreakSpec7AreRefused) {
  const std::size_t n = 600, w = 4;
  const auto e = elements(n, w, 9);
  const auto good = payload_of(e, w);
  const auto first = frame_of(plane(e, w, 0));
  using C = ErrorClass;

  std::vector<std::uint8_t> three;  // w − 1 frames
  for (std::size_t p = 0; p < 3; ++p) {
    const auto f = frame_of(plane(e, w, p));
    three.insert(three.end(), f.begin(), f.end());
  }
  expect_refused(three, n, w, C::Malformed, "end before zstd frame 3 of 4");
  auto five = good;  // w + 1 frames
  five.insert(five.end(), first.begin(), first.end());
  expect_refused(five, n, w, C::Malformed, "follow the last of the 4 zstd frames");
  auto trailing = good;
  trailing.push_back(0);
  expect_refused(trailing, n, w, C::Malformed, "1 bytes follow the last");
  // A skippable frame (magic 0x184D2A50) between planes 0 and 1.
  std::vector<std::uint8_t> skippable = first;
  const std::uint8_t skip[] = {0x50, 0x2A, 0x4D, 0x18, 2, 0, 0, 0, 7, 7};
  skippable.insert(skippable.end(), std::begin(skip), std::end(skip));
  skippable.insert(skippable.end(), good.begin() + static_cast<std::ptrdiff_t>(first.size()), good.end());
  expect_refused(skippable, n, w, C::Malformed, "zstd frame 1 of 4 (byte plane 1) does not start with zstd's magic");
  // Plane 2's frame holding one byte less than a plane.
  std::vector<std::uint8_t> short_plane;
  for (std::size_t p = 0; p < w; ++p) {
    auto content = plane(e, w, p);
    if (p == 2) content.pop_back();
    const auto f = frame_of(content);
    short_plane.insert(short_plane.end(), f.begin(), f.end());
  }
  expect_refused(short_plane, n, w, C::Malformed, "holds 599 bytes, the index says 600");
  std::vector<std::uint8_t> unsized;  // plane 0 without Frame_Content_Size
  const auto u = frame_of(plane(e, w, 0), true, false);
  unsized.insert(unsized.end(), u.begin(), u.end());
  unsized.insert(unsized.end(), good.begin() + static_cast<std::ptrdiff_t>(first.size()), good.end());
  expect_refused(unsized, n, w, C::Malformed, "does not carry Frame_Content_Size");
  auto cut = good;  // the last frame cut short
  cut.resize(cut.size() - 3);
  expect_refused(cut, n, w, C::Malformed, "zstd frame 3 of 4 (byte plane 3) does not end within the stored bytes");
  auto flipped = good;  // plane 0's content checksum (its last 4 bytes) wrong
  flipped[first.size() - 1] ^= 0x40;
  expect_refused(flipped, n, w, C::Checksum, "zstd frame 0 of 4 (byte plane 0): the zstd content checksum");
  expect_refused({}, n, w, C::Malformed, "end before zstd frame 0 of 4");
}

}  // namespace
