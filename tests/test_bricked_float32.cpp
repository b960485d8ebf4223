// A bricked regular grid of float32 values (spec §8A.4 with value_encoding
// 3; its bricks of codec 2, or stored): every voxel's 32 bits back through
// boxes, slices and single voxels, −0, infinities, subnormals and NaN
// payloads included; its stored levels of detail (§8A.5) against a dense
// binary64 reference computed here from §12.3; check_file.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "ivol/bricked_writer.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

std::uint32_t bits(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, 4);
  return b;
}

float value(std::uint32_t b) {
  float f;
  std::memcpy(&f, &b, 4);
  return f;
}

// A reconstruction-like volume: a ball in air, a gradient and noise, as
// float32 bits; with `specials`, every 89th voxel one of the patterns a
// float32 copy must keep.
std::vector<std::uint32_t> make_volume(const Dims& d, unsigned seed, bool specials) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  std::vector<std::uint32_t> v(voxel_count(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const double r = std::hypot(x - d[0] / 2.0, y - d[1] / 3.0, z - d[2] / 2.0);
        v[i] = bits((r < d[0] / 3.0 ? 0.06f : 0.0f) + 0.0004f * float(x + y + z) + noise(rng));
      }
  if (specials) {
    const std::uint32_t special[] = {0x80000000u, 0x7FC00001u, 0xFF812345u, 0x7F800000u, 0xFF800000u,
                                     0x00000001u, 0x807FFFFFu, 0x7F7FFFFFu, 0x7FA00000u};
    for (std::size_t k = 0; k < v.size(); k += 89) v[k] = special[(k / 89) % std::size(special)];
  }
  return v;
}

std::string write(const std::string& name, const Dims& d, const std::vector<std::uint32_t>& v, unsigned log2,
                  int zstd_level = 3) {
  const std::string path = ivol::test::temp_path(name);
  BrickedOptions o;
  o.brick_log2 = log2;
  o.zstd_level = zstd_level;
  o.encoding = ValueEncoding::Float32;
  o.threads = 2;
  BrickedGridWriter writer(path, d, o);
  while (writer.next_layer_count() > 0)
    writer.add_layer(v.data() + std::size_t{writer.next_layer_first()} * d[0] * d[1]);
  writer.finish(Metadata{});
  return path;
}

std::vector<std::uint32_t> bits_of(Reader& r, const Box& box, unsigned lod = 0) {
  const auto bytes = r.read_box_bits(box, lod);
  std::vector<std::uint32_t> out(bytes.size() / 4);
  std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

std::vector<std::uint32_t> crop(const std::vector<std::uint32_t>& v, const Dims& d, const Box& b) {
  std::vector<std::uint32_t> out;
  for (std::uint32_t z = b.lo[2]; z < b.hi[2]; ++z)
    for (std::uint32_t y = b.lo[1]; y < b.hi[1]; ++y)
      for (std::uint32_t x = b.lo[0]; x < b.hi[0]; ++x) out.push_back(v[(std::size_t{z} * d[1] + y) * d[0] + x]);
  return out;
}

TEST(BrickedFloat32, EveryVoxelsBitsComeBackThroughBoxesSlicesAndVoxels) {
  const Dims d{37, 21, 45};  // bricks at every edge smaller than the brick size
  for (unsigned log2 : {3u, 5u}) {
    const auto v = make_volume(d, 1 + log2, true);
    const std::string path = write("bricked32.ivol", d, v, log2);
    Reader r(path);
    EXPECT_EQ(r.layout().kind, StructureKind::Bricked);
    EXPECT_EQ(r.layout().encoding, ValueEncoding::Float32);
    ASSERT_EQ(bits_of(r, full_box(d)), v);
    for (int axis = 0; axis < 3; ++axis) {
      const Box s = slice_box(d, static_cast<Axis>(axis), d[axis] / 2 + 1);
      EXPECT_EQ(bits_of(r, s), crop(v, d, s)) << axis;
    }
    std::mt19937 rng(5);
    for (int t = 0; t < 20; ++t) {
      Box b;
      for (int a = 0; a < 3; ++a) {
        b.lo[a] = rng() % d[a];
        b.hi[a] = b.lo[a] + 1 + rng() % (d[a] - b.lo[a]);
      }
      ASSERT_EQ(bits_of(r, b), crop(v, d, b)) << b.to_string();
      EXPECT_EQ(r.voxel_bits(b.lo[0], b.lo[1], b.lo[2]), v[(std::size_t{b.lo[2]} * d[1] + b.lo[1]) * d[0] + b.lo[0]]);
    }
    // Stored levels against the Reader's own sums, and every block's rules.
    const CheckReport report = check_file(path);
    EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
    const std::uint64_t edge = 1u << log2;
    std::uint64_t bricks = 1;
    for (int a = 0; a < 3; ++a) bricks *= (d[a] + edge - 1) / edge;
    std::uint64_t values_blocks = 0, compressed = 0;
    for (const BlockInfo& b : r.info().blocks)
      if (b.stream == 3) {
        ++values_blocks;
        // Codecs 3 and 4 hold 16-bit values; codec 6 where the noise makes it smaller.
        EXPECT_TRUE(b.codec == 2 || b.codec == 0 || b.codec == 6) << int{b.codec};
        compressed += b.codec != 0;
      }
    EXPECT_EQ(values_blocks, bricks);
    EXPECT_GT(2 * compressed, values_blocks);
  }
}

// From zstd level 13 the bricks' byte planes are a frame each (codec 5)
// where a brick holds 4096 values or more, codec 2 below (or codec 6 where
// the noise makes that smaller): every bit comes back, the stored levels of
// detail too, and check_file passes.
TEST(BrickedFloat32, AtLevel13AndUpBricksAreAFrameAPlane) {
  const Dims d{40, 35, 33};
  auto v = make_volume(d, 4, true);
  // The first layer of bricks without noise, a gradient alone: there zstd's
  // planes beat codec 6, which stores the low bytes as they are.
  for (std::uint32_t z = 0; z < 16; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x)
        v[(std::size_t{z} * d[1] + y) * d[0] + x] = bits(0.0004f * float(x + y + z));
  for (int level : {13, 19}) {
    const std::string path = write("bricked32-c5.ivol", d, v, 4, level);
    Reader r(path);
    ASSERT_EQ(bits_of(r, full_box(d)), v);
    ReaderOptions summed;
    summed.stored_levels = false;
    Reader computed(path, summed);
    for (unsigned lod : {1u, 2u, 3u})
      EXPECT_EQ(bits_of(r, full_box(d, lod), lod), bits_of(computed, full_box(d, lod), lod));
    const CheckReport report = check_file(path);
    EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
    std::uint64_t frames = 0, planes = 0;
    for (const BlockInfo& b : r.info().blocks) {
      if (b.stream == 3 && b.element_count == 4096) EXPECT_TRUE(b.codec == 5 || b.codec == 6) << b.first_element;
      if (b.codec == 5) EXPECT_GE(b.element_count, 4096u);
      frames += b.codec == 5;
      planes += b.codec == 2;
    }
    EXPECT_GT(frames, 0u);
    EXPECT_GT(planes, 0u);  // the edge bricks and small stored levels
  }
}

// Bricks of random bits do not compress: they are stored (codec 0), not
// left larger than themselves.
TEST(BrickedFloat32, RandomBricksAreStored) {
  const Dims d{16, 16, 16};
  std::mt19937 rng(7);
  std::vector<std::uint32_t> v(voxel_count(d));
  for (auto& x : v) x = rng();
  const std::string path = write("bricked32-random.ivol", d, v, 3);
  Reader r(path);
  EXPECT_EQ(bits_of(r, full_box(d)), v);
  for (const BlockInfo& b : r.info().blocks)
    if (b.stream == 3) EXPECT_EQ(b.codec, 0);
}

// §12.3: a level-of-detail value is the binary64 sum of its cell's decoded
// values in the order z, y, x, over their count, rounded once to float32;
// a NaN in the cell makes it NaN (0x7FC00000, §9), an infinity infinite.
// The stored levels (from level 3) and the Reader's own sums (stored levels
// off) against that, computed here.
TEST(BrickedFloat32, LevelsOfDetailAreTheMeansOfSpec12_3) {
  const Dims d{70, 41, 75};  // depth 7: stored levels 3 .. 7
  auto v = make_volume(d, 9, false);
  v[1000] = 0x7F800000u;   // +inf
  v[60000] = 0xFFC00123u;  // a NaN
  v[70000] = 0x80000000u;  // −0
  const std::string path = write("bricked32-lod.ivol", d, v, 4);
  ReaderOptions summed;
  summed.stored_levels = false;
  Reader stored(path), computed(path, summed);
  std::uint64_t stored_blocks = 0;
  for (const BlockInfo& b : stored.info().blocks) stored_blocks += b.stream == 7;
  EXPECT_GT(stored_blocks, 0u);
  for (unsigned lod : {1u, 3u, 5u, 7u}) {
    const Dims ld = lod_dims(d, lod);
    const auto from_stored = bits_of(stored, full_box(d, lod), lod);
    const auto from_sums = bits_of(computed, full_box(d, lod), lod);
    std::size_t n = 0;
    for (std::uint32_t k = 0; k < ld[2]; ++k)
      for (std::uint32_t j = 0; j < ld[1]; ++j)
        for (std::uint32_t i = 0; i < ld[0]; ++i, ++n) {
          double sum = 0.0, count = 0.0;
          for (std::uint32_t z = k << lod; z < std::min(d[2], (k + 1) << lod); ++z)
            for (std::uint32_t y = j << lod; y < std::min(d[1], (j + 1) << lod); ++y)
              for (std::uint32_t x = i << lod; x < std::min(d[0], (i + 1) << lod); ++x, count += 1)
                sum += value(v[(std::size_t{z} * d[1] + y) * d[0] + x]);
          const double mean = sum / count;
          const std::uint32_t want = std::isnan(mean) ? 0x7FC00000u : bits(static_cast<float>(mean));
          ASSERT_EQ(from_stored[n], want) << "level " << lod << ", element " << n;
          ASSERT_EQ(from_sums[n], want) << "level " << lod << ", element " << n;
        }
  }
  EXPECT_TRUE(check_file(path).ok());
}

TEST(BrickedFloat32, ValuesOfTheOtherWidthAreRefused) {
  const Dims d{8, 8, 8};
  BrickedOptions o;
  o.brick_log2 = 3;
  o.encoding = ValueEncoding::Float32;
  std::vector<std::uint16_t> narrow(voxel_count(d));
  std::vector<std::uint32_t> wide(voxel_count(d));
  {
    BrickedGridWriter writer(ivol::test::temp_path("w32.ivol"), d, o);
    EXPECT_THROW(writer.add_layer(narrow.data()), Error);
  }
  o.encoding = ValueEncoding::Binary16;
  BrickedGridWriter writer(ivol::test::temp_path("w16.ivol"), d, o);
  EXPECT_THROW(writer.add_layer(wide.data()), Error);
}

}  // namespace
