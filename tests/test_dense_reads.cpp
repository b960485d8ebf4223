// The octree read's dense path (issue 19): where a node's cube lies wholly
// inside the requested box, the reader descends its subtree without frames
// and writes each level-(D-1) node's eight values as one 2x2x2 cube. Its
// results must equal, voxel for voxel,
// - the dense source volume (lossless builds: every voxel its own value, so
//   a child written at the wrong octant or offset shows),
// - the per-leaf walk (a read that lists damage, which never takes the
//   dense path),
// - the per-voxel descent of Reader::voxel_value at coarser levels,
// for octrees with coarse and fine leaves side by side, boxes that cut
// subtrees at odd offsets, every value encoding and codec, and blocks too
// small to hold a node's eight values together.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/encoding.hpp"
#include "ivol/reader.hpp"
#include "hostile_files.hpp"
#include "ivol/error.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

std::uint64_t at(const Dims& d, std::uint64_t x, std::uint64_t y, std::uint64_t z) { return (z * d[1] + y) * d[0] + x; }

// Integer values below 2048 (exact in binary16, uint16 and float32): a
// piecewise constant volume on aligned cubes of side 8 (coarse leaves),
// side 2 (leaves one level above the voxels, next to inner siblings) and
// side 1 (noise: every voxel a leaf), in slabs along z, so that nodes of
// every level hold both leaves and inner children.
std::vector<std::uint16_t> make_source(const Dims& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint16_t> table(1u << 16);
  for (auto& v : table) v = static_cast<std::uint16_t>(rng() % 2048);
  std::vector<std::uint16_t> out(std::uint64_t{d[0]} * d[1] * d[2]);
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x) {
        // Slabs of 16: cubes of 8, of 2, then noise; the x half past 24 is
        // noise throughout, so that every slab also holds mixed nodes.
        const unsigned band = (z / 16) % 3;
        const unsigned s = x >= 24 ? 0 : band == 0 ? 3 : band == 1 ? 1 : 0;
        const std::uint32_t key = ((x >> s) * 73856093u) ^ ((y >> s) * 19349663u) ^ ((z >> s) * 83492791u) ^ (s << 28);
        out[at(d, x, y, z)] = s == 0 ? static_cast<std::uint16_t>(rng() % 2048) : table[key & 0xFFFFu];
      }
  return out;
}

std::vector<float> crop(const std::vector<std::uint16_t>& source, const Dims& d, const Box& box) {
  std::vector<float> out;
  out.reserve(box.voxel_count());
  for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
    for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
      for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x) out.push_back(source[at(d, x, y, z)]);
  return out;
}

struct Case {
  Dims dims;
  ValueEncoding encoding;
  std::uint32_t block_bytes;
  bool compress;
  bool byte_planes;
};

std::string name_of(const Case& c) {
  return std::string(encoding_name(c.encoding)) + " " + std::to_string(c.dims[0]) + "x" + std::to_string(c.dims[1]) +
         "x" + std::to_string(c.dims[2]) + " blocks of " + std::to_string(c.block_bytes) + " B, " +
         (c.compress ? (c.byte_planes ? "codec 2" : "codec 1") : "codec 0");
}

std::string write_case(const Case& c, const std::vector<std::uint16_t>& source, const std::string& name) {
  BuildOptions build;
  build.encoding = c.encoding;
  BuildResult result = [&] {
    if (c.encoding == ValueEncoding::UInt16) return build_octree(source.data(), c.dims, build);
    const std::vector<float> as_float(source.begin(), source.end());
    return build_octree(as_float.data(), c.dims, build);
  }();
  EXPECT_TRUE(result.lossless) << name_of(c);
  EXPECT_LT(result.kept_voxels, source.size()) << "the volume must hold coarse leaves too";
  WriteOptions write;
  write.block_bytes = c.block_bytes;
  write.compress = c.compress;
  write.byte_planes = c.byte_planes;
  const std::string path = test::temp_path(name);
  write_octree(result.octree, Metadata{}, path, write);
  return path;
}

// Boxes with odd offsets and sizes, boxes of whole aligned subtrees shifted
// by one voxel, single rows and slices, and the whole level.
std::vector<Box> boxes_for(const Dims& d, std::mt19937& rng) {
  std::vector<Box> boxes{full_box(d, 0)};
  for (int n = 0; n < 24; ++n) {
    Box b;
    for (int a = 0; a < 3; ++a) {
      std::uint32_t p = rng() % d[a], q = rng() % d[a];
      if (p > q) std::swap(p, q);
      b.lo[a] = p;
      b.hi[a] = q + 1;
    }
    boxes.push_back(b);
  }
  for (std::uint32_t shift : {0u, 1u, 3u})
    for (std::uint32_t side : {8u, 16u, 32u}) {
      Box b;
      for (int a = 0; a < 3; ++a) {
        b.lo[a] = std::min(side + shift, d[a] - 1);
        b.hi[a] = std::min(b.lo[a] + side, d[a]);
      }
      boxes.push_back(b);
    }
  for (Axis axis : {Axis::X, Axis::Y, Axis::Z}) boxes.push_back(slice_box(d, axis, 17));
  boxes.push_back(Box{{0, 5, 9}, {d[0], 6, 10}});  // one row
  return boxes;
}

void check_case(const Case& c, unsigned seed) {
  SCOPED_TRACE(name_of(c));
  const std::vector<std::uint16_t> source = make_source(c.dims, seed);
  const std::string path = write_case(c, source, "dense_" + std::to_string(seed) + ".ivol");
  Reader reader(path);
  ASSERT_EQ(reader.layout().encoding, c.encoding);
  std::mt19937 rng(seed);
  for (const Box& box : boxes_for(c.dims, rng)) {
    SCOPED_TRACE(box.to_string());
    const std::vector<float> expected = crop(source, c.dims, box);
    // The dense path, against the source.
    ASSERT_EQ(reader.read_box(box), expected);
    // Stored bits, the other sink of the same walk.
    const std::vector<std::uint8_t> bits = reader.read_box_bits(box);
    const std::size_t width = encoding_width(c.encoding);
    ASSERT_EQ(bits.size(), expected.size() * width);
    for (std::size_t i = 0; i < expected.size(); ++i) {
      std::uint32_t code = 0;
      for (std::size_t b = 0; b < width; ++b) code |= std::uint32_t{bits[i * width + b]} << (8 * b);
      ASSERT_EQ(decode_value(c.encoding, code), expected[i]) << "voxel " << i;
    }
    // The per-leaf walk (listing damage turns the dense path off).
    std::vector<DamagedRegion> damaged;
    ASSERT_EQ(reader.read_box(box, 0, &damaged), expected);
    EXPECT_TRUE(damaged.empty());
  }
  // Coarser levels: the values of the target level's nodes, against the
  // per-leaf walk and, on small boxes, the per-voxel descent.
  for (unsigned lod = 1; lod <= 3; ++lod) {
    const Dims d = lod_dims(c.dims, lod);
    for (const Box& box : {full_box(c.dims, lod), Box{{1, 0, 1}, {d[0], d[1] - 1, d[2]}}}) {
      SCOPED_TRACE("level of detail " + std::to_string(lod) + " " + box.to_string());
      const std::vector<float> dense = reader.read_box(box, lod);
      std::vector<DamagedRegion> damaged;
      ASSERT_EQ(dense, reader.read_box(box, lod, &damaged));
      std::size_t n = 0;
      for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
        for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
          for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x, ++n)
            ASSERT_EQ(dense[n], static_cast<float>(reader.voxel_value(x, y, z, lod))) << x << "," << y << "," << z;
    }
  }
}

TEST(DenseReads, EqualSourcePerLeafWalkAndPerVoxelDescent) {
  unsigned seed = 1;
  for (const Dims& dims : {Dims{64, 64, 64}, Dims{45, 38, 52}})
    for (ValueEncoding encoding : {ValueEncoding::UInt16, ValueEncoding::Binary16, ValueEncoding::Float32})
      // 1000-byte blocks hold 500 or 250 values: a node's eight values
      // often straddle two blocks.
      for (std::uint32_t block_bytes : {1000u, 16384u}) check_case({dims, encoding, block_bytes, true, true}, seed++);
}

TEST(DenseReads, EveryCodec) {
  unsigned seed = 100;
  for (ValueEncoding encoding : {ValueEncoding::UInt16, ValueEncoding::Float32}) {
    check_case({Dims{40, 48, 33}, encoding, 4096, false, false}, seed++);  // codec 0
    check_case({Dims{40, 48, 33}, encoding, 4096, true, false}, seed++);   // codec 1
  }
}

// A whole level is read on several threads (whole_level.hpp): subtrees
// below level 3 each a task, their blocks decoded by the threads that need
// them. The result must not depend on the number of threads: it must equal
// the source, the per-leaf walk and the per-voxel descent.
Reader with_threads(const std::string& path, unsigned threads) {
  ReaderOptions options;
  options.threads = threads;
  return Reader(path, options);
}

TEST(DenseReads, WholeLevelOnSeveralThreadsEqualsSourceWalkAndDescent) {
  unsigned seed = 200;
  for (const Case& c : {Case{Dims{64, 64, 64}, ValueEncoding::UInt16, 1000, true, true},
                        Case{Dims{45, 38, 52}, ValueEncoding::Binary16, 1000, true, true},
                        Case{Dims{64, 64, 64}, ValueEncoding::Float32, 16384, true, false},
                        Case{Dims{40, 48, 33}, ValueEncoding::UInt16, 4096, false, false}}) {
    SCOPED_TRACE(name_of(c));
    const std::vector<std::uint16_t> source = make_source(c.dims, seed);
    const std::string path = write_case(c, source, "dense_whole_" + std::to_string(seed++) + ".ivol");
    Reader walk(path);
    for (unsigned threads : {1u, 2u, 3u, 8u}) {
      SCOPED_TRACE(std::to_string(threads) + " threads");
      Reader reader = with_threads(path, threads);
      const Box whole = full_box(c.dims, 0);
      const std::vector<float> expected = crop(source, c.dims, whole);
      ASSERT_EQ(reader.read_box(whole), expected);
      const std::vector<std::uint8_t> bits = reader.read_box_bits(whole);
      const std::size_t width = encoding_width(c.encoding);
      ASSERT_EQ(bits.size(), expected.size() * width);
      for (std::size_t i = 0; i < expected.size(); ++i) {
        std::uint32_t code = 0;
        for (std::size_t b = 0; b < width; ++b) code |= std::uint32_t{bits[i * width + b]} << (8 * b);
        ASSERT_EQ(decode_value(c.encoding, code), expected[i]) << "voxel " << i;
      }
      for (unsigned lod = 1; lod <= 3; ++lod) {
        SCOPED_TRACE("level of detail " + std::to_string(lod));
        const std::vector<float> level = reader.read_lod(lod);
        std::vector<DamagedRegion> damaged;
        ASSERT_EQ(level, walk.read_box(full_box(c.dims, lod), lod, &damaged));
        const Dims d = lod_dims(c.dims, lod);
        std::size_t n = 0;
        for (std::uint32_t z = 0; z < d[2]; ++z)
          for (std::uint32_t y = 0; y < d[1]; ++y)
            for (std::uint32_t x = 0; x < d[0]; ++x, ++n)
              ASSERT_EQ(level[n], static_cast<float>(walk.voxel_value(x, y, z, lod))) << x << "," << y << "," << z;
      }
      EXPECT_GT(reader.io_stats().blocks_decoded, 0u);
    }
  }
}

// The voxel (x, y, z) of hostile::write_full_octree: its value is its index
// in the values stream, found from the octants on its path (a full tree is
// numbered level by level, each level in octant order).
float full_octree_value(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  std::uint64_t position = 0;  // of the level-5 node holding the voxel, within its level
  for (unsigned level = 0; level < 5; ++level) {
    const unsigned shift = 5 - level;
    position = 8 * position + (((x >> shift) & 1u) | (((y >> shift) & 1u) << 1) | (((z >> shift) & 1u) << 2));
  }
  const std::uint64_t first_level5 = (1 + 8 + 64 + 512 + 4096);
  const unsigned c = (x & 1u) | ((y & 1u) << 1) | ((z & 1u) << 2);
  return static_cast<float>(1 + 8 * (first_level5 + position) + c);
}

TEST(DenseReads, WholeLevelRefusesNumberingBrokenWithinAndBetweenSubtrees) {
  const std::string valid = test::temp_path("full_octree.ivol");
  test::hostile::write_full_octree(valid, 0);
  const Dims dims{64, 64, 64};
  for (unsigned threads : {1u, 2u, 4u}) {
    SCOPED_TRACE(std::to_string(threads) + " threads");
    Reader good = with_threads(valid, threads);
    const std::vector<float> whole = good.read_box(full_box(dims, 0));
    std::size_t n = 0;
    for (std::uint32_t z = 0; z < 64; ++z)
      for (std::uint32_t y = 0; y < 64; ++y)
        for (std::uint32_t x = 0; x < 64; ++x, ++n)
          ASSERT_EQ(whole[n], full_octree_value(x, y, z)) << x << "," << y << "," << z;
    for (unsigned shared_from : {8u, 9u}) {
      SCOPED_TRACE(shared_from == 8 ? "between two subtrees" : "within one subtree");
      const std::string broken = test::temp_path("full_octree_dag_" + std::to_string(shared_from) + ".ivol");
      test::hostile::write_full_octree(broken, shared_from);
      Reader bad = with_threads(broken, threads);
      auto expect_refused = [&](const std::function<void()>& read, const std::string& what) {
        try {
          read();
          ADD_FAILURE() << what << " read the DAG";
        } catch (const Error& e) {
          EXPECT_EQ(e.error_class(), ErrorClass::Malformed) << e.what();
          EXPECT_NE(std::string(e.what()).find("breadth-first order requires"), std::string::npos) << e.what();
        }
      };
      // Levels of detail 0 and 1 visit the level-4 node words, split into
      // subtrees at level 3.
      expect_refused([&] { bad.read_box(full_box(dims, 0)); }, "the whole volume");
      expect_refused([&] { bad.read_box_bits(full_box(dims, 0)); }, "the whole volume's stored bits");
      expect_refused([&] { bad.read_lod(1); }, "level of detail 1");
      // The one-thread walk of a box short of the whole refuses it too.
      expect_refused([&] { bad.read_box(Box{{0, 0, 0}, {64, 64, 63}}); }, "all but one slice");
      // Level of detail 2 takes the level-4 nodes' values, not their words:
      // the same as the valid file's.
      EXPECT_EQ(bad.read_lod(2), good.read_lod(2));
    }
  }
}

// Flips one byte in the middle of block `index`'s stored bytes (its CRC
// then fails).
void damage_block(const std::string& path, const BlockInfo& block) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  const auto at = static_cast<std::streamoff>(block.file_offset + block.stored_size / 2);
  char byte = 0;
  f.seekg(at);
  f.read(&byte, 1);
  byte = static_cast<char>(byte ^ 0x55);
  f.seekp(at);
  f.write(&byte, 1);
  ASSERT_TRUE(f.good());
}

TEST(DenseReads, WholeLevelOnSeveralThreadsReportsADamagedBlock) {
  const Case c{Dims{64, 64, 64}, ValueEncoding::UInt16, 1000, true, true};
  const std::vector<std::uint16_t> source = make_source(c.dims, 300);
  for (const std::uint8_t stream : {std::uint8_t{3}, std::uint8_t{2}}) {
    SCOPED_TRACE(stream == 3 ? "a values block" : "a nodes block");
    const std::string path = write_case(c, source, "dense_damaged_" + std::to_string(stream) + ".ivol");
    // The middle block of the stream at the deepest level it has.
    std::size_t damaged_index = 0;
    {
      const Reader reader(path);
      std::vector<std::size_t> candidates;
      unsigned deepest = 0;
      for (std::size_t b = 0; b < reader.info().blocks.size(); ++b)
        if (reader.info().blocks[b].stream == stream) deepest = std::max<unsigned>(deepest, reader.info().blocks[b].level);
      for (std::size_t b = 0; b < reader.info().blocks.size(); ++b)
        if (reader.info().blocks[b].stream == stream && reader.info().blocks[b].level == deepest) candidates.push_back(b);
      ASSERT_GT(candidates.size(), 2u);
      damaged_index = candidates[candidates.size() / 2];
      damage_block(path, reader.info().blocks[damaged_index]);
    }
    const std::string named = "block " + std::to_string(damaged_index) + " (";
    for (unsigned threads : {1u, 2u, 4u}) {
      SCOPED_TRACE(std::to_string(threads) + " threads");
      Reader reader = with_threads(path, threads);
      auto expect_checksum = [&](const std::function<void()>& read, const std::string& what) {
        try {
          read();
          ADD_FAILURE() << what << " read the damaged file without an error";
        } catch (const Error& e) {
          EXPECT_EQ(e.error_class(), ErrorClass::Checksum) << e.what();
          EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
        }
      };
      // Twice: the second read meets the block the Reader remembers as failed.
      expect_checksum([&] { reader.read_box(full_box(c.dims, 0)); }, "the whole volume");
      expect_checksum([&] { reader.read_box(full_box(c.dims, 0)); }, "the whole volume again");
      expect_checksum([&] { reader.read_box_bits(full_box(c.dims, 0)); }, "the whole volume's stored bits");
      expect_checksum(
          [&] {
            Reader fresh = with_threads(path, threads);
            fresh.read_box(full_box(c.dims, 0));
          },
          "the whole volume by a new Reader");
      // A salvaging read lists the damage and fills the rest from the source.
      std::vector<DamagedRegion> damaged;
      const std::vector<float> salvaged = reader.read_box(full_box(c.dims, 0), 0, &damaged);
      ASSERT_FALSE(damaged.empty());
      EXPECT_NE(damaged[0].message.find(named), std::string::npos) << damaged[0].message;
      const std::vector<float> expected = crop(source, c.dims, full_box(c.dims, 0));
      std::size_t differ = 0;
      for (std::size_t i = 0; i < expected.size(); ++i) differ += salvaged[i] != expected[i];
      EXPECT_GT(differ, 0u);
      EXPECT_LT(differ, expected.size() / 4);
    }
  }
}

// The vector writers of a 4^3 cube (cube_writers.hpp) convert as the
// scalar path does: every binary16 code that is not a NaN (the float source
// of build_octree cannot carry a NaN's payload; tests/python checks those),
// each voxel a leaf, against the source and, bit for bit, the per-leaf walk.
TEST(DenseReads, CubeWritersConvertEveryBinary16CodeAsTheScalarPath) {
  const Dims dims{64, 64, 64};
  std::vector<std::uint16_t> codes;
  for (std::uint32_t h = 0; h < 65536; ++h)
    if (((h >> 10) & 0x1Fu) != 31 || (h & 0x3FFu) == 0) codes.push_back(static_cast<std::uint16_t>(h));
  std::mt19937 rng(7);
  std::vector<float> source(std::uint64_t{dims[0]} * dims[1] * dims[2]);
  for (std::size_t i = 0; i < source.size(); ++i) {
    if (i % codes.size() == 0) std::shuffle(codes.begin(), codes.end(), rng);
    source[i] = binary16_to_float(codes[i % codes.size()]);
  }
  BuildOptions build;
  build.encoding = ValueEncoding::Binary16;
  const BuildResult result = build_octree(source.data(), dims, build);
  ASSERT_TRUE(result.lossless);
  const std::string path = test::temp_path("dense_binary16_codes.ivol");
  write_octree(result.octree, Metadata{}, path, WriteOptions{});
  for (unsigned threads : {1u, 2u}) {
    Reader reader = with_threads(path, threads);
    const Box whole = full_box(dims, 0);
    const std::vector<float> dense = reader.read_box(whole);
    std::vector<DamagedRegion> damaged;
    const std::vector<float> walked = reader.read_box(whole, 0, &damaged);
    ASSERT_EQ(dense.size(), source.size());
    ASSERT_EQ(std::memcmp(dense.data(), walked.data(), dense.size() * sizeof(float)), 0);
    for (std::size_t i = 0; i < source.size(); ++i)
      ASSERT_EQ(std::memcmp(&dense[i], &source[i], sizeof(float)), 0) << "voxel " << i << ": " << dense[i];
    // A box that is not the whole volume takes the cube writers too.
    const Box inner{{4, 8, 12}, {60, 56, 52}};
    const std::vector<float> part = reader.read_box(inner);
    ASSERT_EQ(part, reader.read_box(inner, 0, &damaged));
  }
}

}  // namespace
