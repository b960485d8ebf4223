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

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "ivol/build.hpp"
#include "ivol/encoding.hpp"
#include "ivol/reader.hpp"
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

}  // namespace
