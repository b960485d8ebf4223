// A bricked grid's stored levels of detail (spec §8A.5, stream 7): the
// writer stores every level from 3 on; each equals, bit for bit, the level
// summed from full resolution (§12.3), computed here independently and by
// the Reader without them; a preview reads them instead of the volume;
// check_file finds a stored level that differs, in a file whose checksums
// are all valid.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include "ivol/binary16.hpp"
#include "ivol/bricked_writer.hpp"
#include "ivol/check.hpp"
#include "ivol/encoding.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

std::vector<std::uint16_t> noisy_volume(const Dims& d, ValueEncoding e, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.004f);
  std::vector<std::uint16_t> v(voxel_count(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const double r = std::hypot(x - d[0] / 2.0, y - d[1] / 2.5, z - d[2] / 2.0);
        const float m = (r < d[0] / 3.0 ? 0.05f : 0.004f) + noise(rng);
        v[i] = e == ValueEncoding::UInt16 ? static_cast<std::uint16_t>(std::clamp(m * 400000.0f, 0.0f, 65535.0f))
                                          : float_to_binary16(m);
      }
  if (e == ValueEncoding::Binary16) {  // -0, NaNs with payloads, infinities, subnormals
    const std::uint16_t special[] = {0x8000, 0x7E01, 0xFD00, 0x7C00, 0xFC00, 0x0001, 0x8001};
    for (std::size_t k = 0; k < v.size(); k += 193) v[k] = special[(k / 193) % 7];
  }
  return v;
}

std::string write(const std::string& name, const Dims& d, const std::vector<std::uint16_t>& v, ValueEncoding e,
                  unsigned log2, unsigned first_stored_level = 3) {
  const std::string path = test::temp_path(name);
  BrickedOptions o;
  o.brick_log2 = log2;
  o.encoding = e;
  o.first_stored_level = first_stored_level;
  BrickedGridWriter writer(path, d, o);
  while (writer.next_layer_count() > 0)
    writer.add_layer(v.data() + std::size_t{writer.next_layer_first()} * d[0] * d[1]);
  writer.finish(Metadata{});
  return path;
}

std::vector<std::uint16_t> bits_of(Reader& r, const Box& box, unsigned lod) {
  const auto bytes = r.read_box_bits(box, lod);
  std::vector<std::uint16_t> out(bytes.size() / 2);
  std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

double decoded(ValueEncoding e, std::uint16_t bits) {
  return e == ValueEncoding::Binary16 ? binary16_to_double(bits) : static_cast<double>(bits);
}

// Level `lod` of `v` by spec §12.3, written out here: the binary64 sum in
// the order z, y, x from +0.0, over the voxel count, encoded once.
std::vector<std::uint16_t> level_of(const std::vector<std::uint16_t>& v, const Dims& d, ValueEncoding e, unsigned lod) {
  const Dims ld = lod_dims(d, lod);
  std::vector<std::uint16_t> out;
  for (std::uint32_t k = 0; k < ld[2]; ++k)
    for (std::uint32_t j = 0; j < ld[1]; ++j)
      for (std::uint32_t i = 0; i < ld[0]; ++i) {
        double sum = 0.0;
        double count = 0.0;
        for (std::uint64_t z = std::uint64_t{k} << lod; z < std::min<std::uint64_t>(d[2], (k + 1ull) << lod); ++z)
          for (std::uint64_t y = std::uint64_t{j} << lod; y < std::min<std::uint64_t>(d[1], (j + 1ull) << lod); ++y)
            for (std::uint64_t x = std::uint64_t{i} << lod; x < std::min<std::uint64_t>(d[0], (i + 1ull) << lod);
                 ++x, count += 1.0)
              sum = sum + decoded(e, v[(z * d[1] + y) * d[0] + x]);
        out.push_back(static_cast<std::uint16_t>(encode_value(e, sum / count)));
      }
  return out;
}

TEST(StoredLevels, EveryStoredLevelIsTheSumOfSpec12_3) {
  struct Case {
    Dims d;
    unsigned log2;
  };
  // Sizes that are no multiple of the brick; bricks of 2 (levels of many
  // bricks) to 16; a volume one voxel thin along z.
  const Case cases[] = {{{37, 29, 21}, 2}, {{64, 48, 40}, 3}, {{5, 70, 3}, 1}, {{33, 17, 66}, 4}};
  for (const Case& c : cases)
    for (const ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16}) {
      SCOPED_TRACE(std::to_string(c.d[0]) + "x" + std::to_string(c.d[1]) + "x" + std::to_string(c.d[2]) +
                   " bricks of " + std::to_string(1u << c.log2) + " " + encoding_name(e));
      const auto v = noisy_volume(c.d, e, c.log2);
      const std::string path = write("stored_levels.ivol", c.d, v, e, c.log2);
      Reader stored(path);
      ReaderOptions summing;
      summing.stored_levels = false;
      Reader summed(path, summing);
      const unsigned depth = stored.layout().depth;
      std::vector<bool> level_has_blocks(depth + 1, false);
      for (const BlockInfo& b : stored.info().blocks)
        if (b.stream == 7) {
          level_has_blocks[b.level] = true;
          EXPECT_EQ(b.flags, 1) << "stream 7 blocks are ignorable";
        }
      for (unsigned lod = 1; lod <= depth; ++lod) {
        EXPECT_EQ(level_has_blocks[lod], lod >= 3) << "level " << lod;
        const auto want = level_of(v, c.d, e, lod);
        ASSERT_EQ(bits_of(stored, full_box(c.d, lod), lod), want) << "level " << lod << " as read";
        ASSERT_EQ(bits_of(summed, full_box(c.d, lod), lod), want) << "level " << lod << " summed by the Reader";
      }
      // A box inside a stored level, across its bricks.
      if (depth >= 3) {
        const Dims ld = lod_dims(c.d, 3);
        const Box inner{{ld[0] / 3, ld[1] / 3, ld[2] / 3}, {ld[0], ld[1], ld[2]}};
        EXPECT_EQ(bits_of(stored, inner, 3), bits_of(summed, inner, 3));
      }
      const CheckReport report = check_file(path);
      EXPECT_TRUE(report.problems.empty()) << report.problems.front().message;
    }
  // None asked for: no stream 7.
  const Dims d{20, 20, 20};
  const std::string path =
      write("no_levels.ivol", d, noisy_volume(d, ValueEncoding::UInt16, 1), ValueEncoding::UInt16, 2, 0);
  const Reader written(path);  // named: the loop walks its block table
  for (const BlockInfo& b : written.info().blocks) EXPECT_NE(b.stream, 7);
}

// Binary16 levels of cells of 2^15 voxels and more, whose binary64 sums in
// §12.3's order can round: the writer adds such a cell as integers while no
// sum can round and from there on in binary64, in order.
//
// A 32³ volume is one such cell, built so that the rounding changes its
// mean: 8200 voxels of 65504 and one of 256 sum to 16392 · 32768 > 2^29,
// where the binary64 spacing is 2^-23, so each of the 24567 voxels of 2^-24
// that follow is a tie that rounds to the even sum, unchanged. The exact
// mean lies just above 16392, half-way between binary16's 16384 and 16400,
// and encodes as 16400; the binary64 sum's mean is the tie itself and
// encodes as the even 16384, which §12.3 asks for.
TEST(StoredLevels, BinarySixteenLevelsRoundWhereTheSequentialSumRounds) {
  const Dims d{32, 32, 32};
  std::vector<std::uint16_t> v(voxel_count(d), 0x0001);  // 2^-24
  std::fill(v.begin(), v.begin() + 8200, 0x7BFF);        // 65504
  v[8200] = 0x5C00;                                      // 256
  const auto want = level_of(v, d, ValueEncoding::Binary16, 5);
  ASSERT_EQ(want.size(), 1U);
  ASSERT_EQ(binary16_to_double(want[0]), 16384.0) << "the reference does not round as the test means it to";
  const std::string path = write("stored_levels_tie.ivol", d, v, ValueEncoding::Binary16, 3);
  Reader stored(path);
  for (unsigned lod = 3; lod <= 5; ++lod)
    EXPECT_EQ(bits_of(stored, full_box(d, lod), lod), level_of(v, d, ValueEncoding::Binary16, lod)) << "level " << lod;

  // Every binary16 code in order along one row: a cell holds 2^k codes of
  // about one magnitude, so that any code's value counted wrong shows in
  // its cell's mean (levels 3 and 4 exact, 5 on watched).
  const Dims row{65536, 1, 1};
  std::vector<std::uint16_t> codes(65536);
  for (std::size_t c = 0; c < codes.size(); ++c) codes[c] = static_cast<std::uint16_t>(c);
  const std::string row_path = write("stored_levels_codes.ivol", row, codes, ValueEncoding::Binary16, 3);
  Reader row_reader(row_path);
  for (unsigned lod = 3; lod <= row_reader.layout().depth; ++lod)
    EXPECT_EQ(bits_of(row_reader, full_box(row, lod), lod), level_of(codes, row, ValueEncoding::Binary16, lod))
        << "level " << lod;

  // Large values of both signs, cells that round from some row on and
  // cells that never do, infinities and NaNs, over levels 5 to 7.
  const Dims wide{70, 40, 66};
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> large(30000.0f, 65504.0f), small(-2.0f, 2.0f);
  std::vector<std::uint16_t> w(voxel_count(wide));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < wide[2]; ++z)
    for (std::uint32_t y = 0; y < wide[1]; ++y)
      for (std::uint32_t x = 0; x < wide[0]; ++x, ++i) {
        float value = small(rng);
        if (x < 32 && z >= 12) value = large(rng);
        if (x >= 64) value = (x & 1 ? 1.0f : -1.0f) * large(rng);
        if (x >= 32 && x < 64 && y >= 32 && z >= 40) value = -large(rng);
        w[i] = float_to_binary16(value);
      }
  w[(std::size_t{50} * wide[1] + 3) * wide[0] + 5] = 0x7C00;    // +inf
  w[(std::size_t{60} * wide[1] + 35) * wide[0] + 40] = 0x7E01;  // a NaN with a payload
  const std::string wide_path = write("stored_levels_rounding.ivol", wide, w, ValueEncoding::Binary16, 3);
  Reader wide_reader(wide_path);
  for (unsigned lod = 3; lod <= wide_reader.layout().depth; ++lod)
    EXPECT_EQ(bits_of(wide_reader, full_box(wide, lod), lod), level_of(w, wide, ValueEncoding::Binary16, lod))
        << "level " << lod;
  const CheckReport report = check_file(wide_path);
  EXPECT_TRUE(report.problems.empty()) << report.problems.front().message;
}

#if defined(__SSE2__)
// A process may run with subnormals flushed to zero (a library built with
// -ffast-math sets MXCSR's DAZ and FTZ bits when it is loaded, and threads
// made later inherit them): the stored levels must not depend on how the
// processor treats subnormal numbers. Every binary16 code in one row,
// written with DAZ and FTZ set, against the reference summed without.
TEST(StoredLevels, SubnormalsCountWhereTheProcessorFlushesThem) {
  const Dims row{65536, 1, 1};
  std::vector<std::uint16_t> codes(65536);
  for (std::size_t c = 0; c < codes.size(); ++c) codes[c] = static_cast<std::uint16_t>(c);
  std::vector<std::vector<std::uint16_t>> want;
  for (unsigned lod = 0; lod <= depth_for(row); ++lod)
    want.push_back(level_of(codes, row, ValueEncoding::Binary16, lod));
  const unsigned saved = _mm_getcsr();
  _mm_setcsr(saved | 0x8040);  // FTZ and DAZ
  std::string path;
  try {
    path = write("stored_levels_daz.ivol", row, codes, ValueEncoding::Binary16, 3);
  } catch (...) {
    _mm_setcsr(saved);
    throw;
  }
  _mm_setcsr(saved);
  Reader reader(path);
  for (unsigned lod = 3; lod <= reader.layout().depth; ++lod)
    EXPECT_EQ(bits_of(reader, full_box(row, lod), lod), want[lod]) << "level " << lod;
}
#endif

TEST(StoredLevels, APreviewReadsTheStoredLevelNotTheVolume) {
  const Dims d{96, 96, 96};
  const auto v = noisy_volume(d, ValueEncoding::UInt16, 5);
  const std::string path = write("stored_preview.ivol", d, v, ValueEncoding::UInt16, 4);
  const std::uint64_t file_bytes = std::filesystem::file_size(path);
  Reader stored(path);
  stored.reset_io_stats();
  const std::vector<float> preview = stored.read_lod(3);
  const std::uint64_t stored_bytes = stored.io_stats().bytes_read;
  ReaderOptions summing;
  summing.stored_levels = false;
  Reader summed(path, summing);
  summed.reset_io_stats();
  EXPECT_EQ(summed.read_lod(3), preview);
  const std::uint64_t summed_bytes = summed.io_stats().bytes_read;
  EXPECT_LT(stored_bytes, file_bytes / 50) << stored_bytes << " of " << file_bytes;
  EXPECT_GT(summed_bytes, file_bytes * 9 / 10) << summed_bytes << " of " << file_bytes;
}

// A bricked grid of 8³ uint16 values in bricks of 4, written block by block
// here, with level 1 and level 3 stored (level 2 not: a level is stored or
// not, each on its own); `tamper` changes one stored value of level 1.
std::string hand_written(const std::string& name, bool tamper) {
  const Dims d{8, 8, 8};
  std::vector<std::uint16_t> v(512);
  for (std::size_t n = 0; n < v.size(); ++n) v[n] = static_cast<std::uint16_t>(1000 + (n * 37) % 301);
  VolumeLayout layout;
  layout.kind = StructureKind::Bricked;
  layout.cell_log2 = 2;
  layout.dims = d;
  layout.depth = depth_for(d);
  layout.encoding = ValueEncoding::UInt16;
  layout.inner_count.assign(layout.depth + 1, 0);
  const std::string path = test::temp_path(name);
  FileWriter file(path, layout, true);
  file.write_metadata(Metadata{});
  WriteOptions raw;
  raw.compress = false;
  // The bricks of an 8³ or 4³ volume in bricks of 4, in raster order (§8A.4).
  auto write_bricks = [&](const std::vector<std::uint16_t>& values, const Dims& size, Stream stream, unsigned level) {
    std::uint64_t first = 0;
    for (std::uint32_t k = 0; k < size[2]; k += 4)
      for (std::uint32_t j = 0; j < size[1]; j += 4)
        for (std::uint32_t i = 0; i < size[0]; i += 4) {
          std::vector<std::uint16_t> brick;
          for (std::uint32_t z = k; z < std::min(size[2], k + 4); ++z)
            for (std::uint32_t y = j; y < std::min(size[1], j + 4); ++y)
              for (std::uint32_t x = i; x < std::min(size[0], i + 4); ++x)
                brick.push_back(values[(std::size_t{z} * size[1] + y) * size[0] + x]);
          file.append(
              encode_block(stream, level, first, static_cast<std::uint32_t>(brick.size()), 2, brick.data(), raw));
          first += brick.size();
        }
  };
  write_bricks(v, d, Stream::Values, 0);
  std::vector<std::uint16_t> level1 = level_of(v, d, ValueEncoding::UInt16, 1);
  if (tamper) level1[37] = static_cast<std::uint16_t>(level1[37] + 1);
  write_bricks(level1, lod_dims(d, 1), Stream::StoredLevel, 1);
  write_bricks(level_of(v, d, ValueEncoding::UInt16, 3), lod_dims(d, 3), Stream::StoredLevel, 3);
  file.finish(Metadata{}, layout.inner_count);
  return path;
}

TEST(StoredLevels, CheckFileFindsAStoredLevelThatDiffers) {
  const CheckReport sound = check_file(hand_written("levels_sound.ivol", false));
  EXPECT_TRUE(sound.problems.empty()) << sound.problems.front().message;
  const std::string path = hand_written("levels_tampered.ivol", true);
  const CheckReport report = check_file(path);
  ASSERT_EQ(report.problems.size(), 1U);
  EXPECT_EQ(report.problems[0].error_class, ErrorClass::Malformed);
  // Element 37 of level 1 (4³): (1, 1, 2).
  EXPECT_NE(report.problems[0].message.find("stored level of detail 1 differs at (1, 1, 2)"), std::string::npos)
      << report.problems[0].message;
  // Every checksum is valid: a reader that does not verify reads the stored
  // level as it is, as it trusts an octree's averages (spec §8A.5).
  Reader reader(path);
  EXPECT_NE(reader.read_box_bits(full_box(Dims{8, 8, 8}, 1), 1), Reader(path,
                                                                        [] {
                                                                          ReaderOptions o;
                                                                          o.stored_levels = false;
                                                                          return o;
                                                                        }())
                                                                     .read_box_bits(full_box(Dims{8, 8, 8}, 1), 1));
}

}  // namespace
