// Building octrees from dense volumes: every voxel holds its encoded source
// value, levels of detail equal an independent box filter, the structure obeys
// the spec, and memory is what the spec's arithmetic predicts.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;
using test::reference_encode;

std::vector<std::uint32_t> encoded_source(const std::vector<float>& v, ValueEncoding e) {
  std::vector<std::uint32_t> bits(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) bits[i] = reference_encode(e, v[i]);
  return bits;
}

void expect_levels_match_reference(const Octree& tree, const std::vector<std::uint32_t>& bits) {
  const VolumeLayout& L = tree.layout();
  for (unsigned lod = 0; lod <= L.depth; ++lod) {
    const auto reference = test::reference_lod(bits, L.dims, L.encoding, lod);
    const Dims d = lod_dims(L.dims, lod);
    std::uint64_t exact = 0;
    for (std::uint32_t z = 0; z < d[2]; ++z)
      for (std::uint32_t y = 0; y < d[1]; ++y)
        for (std::uint32_t x = 0; x < d[0]; ++x) {
          const std::uint32_t got = tree.voxel_bits(x, y, z, lod);
          const std::uint32_t want = reference[(std::uint64_t{z} * d[1] + y) * d[0] + x];
          ASSERT_LE(test::ulp_distance(L.encoding, got, want), lod == 0 ? 0u : 1u)
              << "lod " << lod << " at " << x << "," << y << "," << z;
          exact += got == want;
        }
    // Rounding the long-double mean and the spec's binary64 recursion differ
    // only at exact ties of the encoding; nearly every value is identical.
    EXPECT_GE(static_cast<double>(exact), 0.99 * voxel_count(d)) << "lod " << lod;
  }
}

struct Case {
  Dims dims;
  ValueEncoding encoding;
  double noise;
};

class BuildLossless : public ::testing::TestWithParam<Case> {};

TEST_P(BuildLossless, VoxelsAndLevelsOfDetail) {
  const Case c = GetParam();
  std::mt19937_64 rng(voxel_count(c.dims) * 31 + static_cast<int>(c.encoding));
  const std::vector<float> volume = test::random_volume(c.dims, rng, c.noise);
  BuildOptions options;
  options.encoding = c.encoding;
  const BuildResult built = build_octree(volume.data(), c.dims, options);
  const Octree& tree = built.octree;
  ASSERT_NO_THROW(tree.validate());
  EXPECT_EQ(tree.layout().depth, depth_for(c.dims));
  EXPECT_EQ(built.kept_voxels <= voxel_count(c.dims), true);
  expect_levels_match_reference(tree, encoded_source(volume, c.encoding));
  if (c.encoding == ValueEncoding::Float32) {
    EXPECT_TRUE(built.lossless);
    EXPECT_EQ(built.max_abs_error, 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, BuildLossless,
    ::testing::Values(Case{{1, 1, 1}, ValueEncoding::Binary16, 0.0}, Case{{2, 2, 2}, ValueEncoding::Binary16, 0.1},
                      Case{{3, 5, 7}, ValueEncoding::Binary16, 0.1}, Case{{257, 1, 2}, ValueEncoding::Binary16, 0.1},
                      Case{{17, 9, 33}, ValueEncoding::Float32, 0.2}, Case{{32, 32, 32}, ValueEncoding::Binary16, 0.0},
                      Case{{40, 33, 29}, ValueEncoding::Binary16, 0.05}, Case{{31, 16, 8}, ValueEncoding::Float32, 0.0},
                      Case{{64, 64, 64}, ValueEncoding::Binary16, 0.01}));

TEST(Build, UInt16SourceIsLossless) {
  const Dims dims{19, 23, 11};
  std::mt19937_64 rng(5);
  std::vector<std::uint16_t> volume(voxel_count(dims));
  for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = (i % 97 < 50) ? 1000 : static_cast<std::uint16_t>(rng());
  BuildOptions options;
  options.encoding = ValueEncoding::UInt16;
  const BuildResult built = build_octree(volume.data(), dims, options);
  ASSERT_NO_THROW(built.octree.validate());
  EXPECT_TRUE(built.lossless);
  std::vector<std::uint32_t> bits(volume.begin(), volume.end());
  expect_levels_match_reference(built.octree, bits);
}

TEST(Build, UInt16WithScaleAndOffsetQuantisesFloats) {
  const Dims dims{16, 16, 16};
  std::mt19937_64 rng(9);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.3);
  BuildOptions options;
  options.encoding = ValueEncoding::UInt16;
  options.value_scale = 1.0 / 4096;
  options.value_offset = -1.0;
  const BuildResult built = build_octree(volume.data(), dims, options);
  ASSERT_NO_THROW(built.octree.validate());
  EXPECT_LE(built.max_abs_error, 0.5 / 4096 + 1e-12);
  EXPECT_FALSE(built.lossless);
  for (std::uint32_t z = 0; z < 16; ++z)
    for (std::uint32_t x = 0; x < 16; ++x)
      EXPECT_NEAR(built.octree.voxel_value(x, 7, z), volume[(z * 16 + 7) * 16 + x], 0.5 / 4096 + 1e-12);
}

TEST(Build, UniformVolumeIsOneLeaf) {
  const Dims dims{100, 37, 64};
  const std::vector<float> volume(voxel_count(dims), 0.125f);
  const BuildResult built = build_octree(volume.data(), dims, BuildOptions{});
  EXPECT_EQ(built.octree.layout().total_inner(), 0u);
  EXPECT_EQ(built.octree.layout().total_values(), 1u);
  EXPECT_EQ(built.octree.voxel_value(99, 36, 63), 0.125);
  EXPECT_NO_THROW(built.octree.validate());
}

TEST(Build, OneDifferentVoxelGivesOneChainOfNodes) {
  const Dims dims{64, 64, 64};
  std::vector<float> volume(voxel_count(dims), 0.0f);
  volume[(std::uint64_t{10} * 64 + 20) * 64 + 30] = 1.0f;
  const BuildResult built = build_octree(volume.data(), dims, BuildOptions{});
  const VolumeLayout& L = built.octree.layout();
  for (unsigned l = 0; l < L.depth; ++l) EXPECT_EQ(L.inner_count[l], 1u) << l;
  EXPECT_EQ(built.octree.voxel_value(30, 20, 10), 1.0);
  EXPECT_EQ(built.octree.voxel_value(31, 20, 10), 0.0);
  // The root's average is 1/64^3, correctly rounded once.
  EXPECT_EQ(built.octree.voxel_bits(0, 0, 0, L.depth), reference_encode(ValueEncoding::Binary16, 1.0 / (64 * 64 * 64)));
}

TEST(Build, FullyRefinedMemoryMatchesSpecArithmetic) {
  // Noise everywhere: no two siblings equal, every node down to the voxels is
  // subdivided. Nodes: (N^3 - 1) / 7 words of 8 bytes; values: 1 + 8 x nodes
  // of 2 bytes: about 3.43 bytes per voxel (the paper's 4 + 12 x sum 8^-h
  // with 4-byte values and 8-byte words on leaves too is 5.71).
  const std::uint32_t n = 32;
  const Dims dims{n, n, n};
  std::vector<float> volume(voxel_count(dims));
  for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = static_cast<float>(i) * 0.001f;
  const BuildResult built = build_octree(volume.data(), dims, BuildOptions{});
  const std::uint64_t voxels = voxel_count(dims);
  const std::uint64_t inner = (voxels - 1) / 7;
  EXPECT_EQ(built.octree.layout().total_inner(), inner);
  EXPECT_EQ(built.octree.memory().node_bytes, 8 * inner);
  EXPECT_EQ(built.octree.memory().value_bytes, 2 * (1 + 8 * inner));
  EXPECT_NEAR(static_cast<double>(built.octree.memory().total()) / voxels, 24.0 / 7.0, 1e-3);
  EXPECT_EQ(built.kept_voxels, voxels);
}

TEST(Build, KeepMaskCoarsensEverythingElseToMeans) {
  // Keep only voxel (5, 6, 7) of a noisy 16^3 volume: the tree is one chain,
  // and every sibling leaf off the chain holds the mean of its octant.
  const Dims dims{16, 16, 16};
  std::mt19937_64 rng(11);
  std::vector<float> volume(voxel_count(dims));
  std::normal_distribution<float> gauss(1.0f, 0.2f);
  for (auto& v : volume) v = gauss(rng);
  std::vector<std::uint8_t> keep(volume.size(), 0);
  keep[(7 * 16 + 6) * 16 + 5] = 1;
  BuildOptions options;
  options.encoding = ValueEncoding::Float32;
  options.keep_mask = keep.data();
  const BuildResult built = build_octree(volume.data(), dims, options);
  const Octree& tree = built.octree;
  ASSERT_NO_THROW(tree.validate());
  EXPECT_FALSE(built.lossless);
  for (unsigned l = 0; l < 4; ++l) EXPECT_EQ(tree.layout().inner_count[l], 1u);
  EXPECT_EQ(tree.voxel_value(5, 6, 7), volume[(7 * 16 + 6) * 16 + 5]);
  // Leaf covering voxel (15, 15, 15): the octant [8,16)^3 of the root.
  double sum = 0;
  for (int z = 8; z < 16; ++z)
    for (int y = 8; y < 16; ++y)
      for (int x = 8; x < 16; ++x) sum += volume[(z * 16 + y) * 16 + x];
  EXPECT_NEAR(tree.voxel_value(15, 15, 15), sum / 512, 1e-6);
  EXPECT_EQ(tree.voxel_value(15, 15, 15), tree.voxel_value(8, 8, 8));
  // Voxel (4, 6, 7) shares the kept voxel's 2x2x2 node, whose children are
  // single voxels: it keeps its own value.
  EXPECT_EQ(tree.voxel_value(4, 6, 7), volume[(7 * 16 + 6) * 16 + 4]);
  // Leaf covering voxel (7, 7, 7): the level-3 sibling [6,8)^3.
  sum = 0;
  for (int z = 6; z < 8; ++z)
    for (int y = 6; y < 8; ++y)
      for (int x = 6; x < 8; ++x) sum += volume[(z * 16 + y) * 16 + x];
  EXPECT_NEAR(tree.voxel_value(7, 7, 7), sum / 8, 1e-6);
}

// A coarse leaf holds the mean of its voxels summed in binary64 child by
// child in octant order (the writer's rule, so that a leaf does not depend
// on how the volume was cut into slabs): with values of 1e20, -1e20 and 1
// any other order gives other sums. The reference below is that rule as
// plainly as it can be written, one voxel at a time; the volume's sides
// are not powers of two (nodes cut by its edges), its leaves up to 32^3,
// and it holds NaN, -0 and infinities.
TEST(Build, CoarseLeavesSumTheirVoxelsInOctantOrder) {
  const Dims dims{45, 38, 53};
  const unsigned depth = depth_for(dims);
  std::mt19937_64 rng(19);
  std::vector<float> volume(voxel_count(dims));
  const float choices[] = {1e20f, -1e20f, 1.0f, 3.0f, -0.0f, 0.5f};
  for (auto& v : volume) v = choices[rng() % 6];
  auto at = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) -> float& {
    return volume[(std::uint64_t{z} * dims[1] + y) * dims[0] + x];
  };
  // Above z = 20 (the large leaves) whole 2^3 cells: in every 4^3 node the
  // first cell (octant order) all 1e20, the third all -1e20, the others
  // small values: the second cell's sum is lost in octant order and kept in
  // any order that adds the third before it, so the cells' order counts as
  // well as the voxels'.
  for (std::uint32_t z = 20; z + 1 < dims[2]; z += 2)
    for (std::uint32_t y = 0; y + 1 < dims[1]; y += 2)
      for (std::uint32_t x = 0; x + 1 < dims[0]; x += 2) {
        const unsigned octant = ((x >> 1) & 1u) | ((y >> 1) & 1u) << 1 | ((z >> 1) & 1u) << 2;
        for (unsigned c = 0; c < 8; ++c) {
          float& v = at(x + (c & 1u), y + ((c >> 1) & 1u), z + ((c >> 2) & 1u));
          v = octant == 0 ? 1e20f : octant == 2 ? -1e20f : choices[2 + rng() % 4];
        }
      }
  at(40, 3, 3) = NAN;                      // a leaf whose mean is NaN
  at(2, 33, 40) = INFINITY;                // one of +inf
  at(20, 20, 50) = -INFINITY;              // one of -inf
  for (std::uint32_t z = 32; z < 40; ++z)  // an 8^3 leaf of -0 and +0 holds +0 (their sum's sign)
    for (std::uint32_t y = 8; y < 16; ++y)
      for (std::uint32_t x = 0; x < 8; ++x) at(x, y, z) = (x + y + z) % 2 ? -0.0f : 0.0f;
  for (std::uint32_t z = 32; z < 40; ++z)  // an 8^3 leaf of -0 alone keeps its sign
    for (std::uint32_t y = 0; y < 8; ++y)
      for (std::uint32_t x = 8; x < 16; ++x) at(x, y, z) = -0.0f;
  // Kept voxels scattered in z < 20 (coarse leaves of 2^3 and 4^3 by the
  // hundred there) and three more elsewhere (leaves of 8^3 to 32^3).
  std::vector<std::uint8_t> keep(volume.size(), 0);
  for (std::uint32_t z = 0; z < 20; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x)
        keep[(std::uint64_t{z} * dims[1] + y) * dims[0] + x] = rng() % 30 == 0;
  for (const auto& v : {Dims{5, 6, 37}, Dims{33, 17, 42}, Dims{44, 37, 52}})
    keep[(std::uint64_t{v[2]} * dims[1] + v[1]) * dims[0] + v[0]] = 1;
  BuildOptions options;
  options.encoding = ValueEncoding::Float32;
  options.keep_mask = keep.data();
  const Octree tree = build_octree(volume.data(), dims, options).octree;
  ASSERT_NO_THROW(tree.validate());

  auto inside = [&](std::uint64_t x, std::uint64_t y, std::uint64_t z) {
    return x < dims[0] && y < dims[1] && z < dims[2];
  };
  // The sum and the kept voxels of the node of `level` at (i, j, k).
  struct Region {
    double sum = 0.0;
    std::uint64_t weight = 0;
    bool kept = false;
  };
  std::function<Region(unsigned, std::uint32_t, std::uint32_t, std::uint32_t)> region =
      [&](unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) {
        Region r;
        if (level == depth) {
          if (!inside(i, j, k)) return r;
          r.sum = 0.0 + static_cast<double>(at(i, j, k));
          r.weight = 1;
          r.kept = keep[(std::uint64_t{k} * dims[1] + j) * dims[0] + i] != 0;
          return r;
        }
        for (unsigned c = 0; c < 8; ++c) {
          const Region child = region(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u));
          if (child.weight == 0) continue;
          r.sum = r.sum + child.sum;
          r.weight += child.weight;
          r.kept = r.kept || child.kept;
        }
        return r;
      };
  std::uint64_t checked = 0, cancelling = 0;
  // Top down: a node without a kept voxel is a leaf; every voxel of it must
  // hold its mean (or, where they are all one value, that value's bits).
  std::function<void(unsigned, std::uint32_t, std::uint32_t, std::uint32_t)> visit =
      [&](unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) {
        const Region r = region(level, i, j, k);
        if (r.weight == 0 || level == depth) return;
        if (r.kept) {
          for (unsigned c = 0; c < 8; ++c)
            visit(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u));
          return;
        }
        const unsigned s = depth - level;
        const std::uint32_t x0 = i << s, y0 = j << s, z0 = k << s;
        const std::uint32_t x1 = std::min<std::uint32_t>(dims[0], x0 + (1u << s));
        const std::uint32_t y1 = std::min<std::uint32_t>(dims[1], y0 + (1u << s));
        const std::uint32_t z1 = std::min<std::uint32_t>(dims[2], z0 + (1u << s));
        const double mean = r.sum / static_cast<double>(r.weight);
        bool uniform = true;
        for (std::uint32_t z = z0; z < z1; ++z)
          for (std::uint32_t y = y0; y < y1; ++y)
            for (std::uint32_t x = x0; x < x1; ++x)
              uniform =
                  uniform && at(x, y, z) == at(x0, y0, z0) && std::signbit(at(x, y, z)) == std::signbit(at(x0, y0, z0));
        for (std::uint32_t z = z0; z < z1; ++z)
          for (std::uint32_t y = y0; y < y1; ++y)
            for (std::uint32_t x = x0; x < x1; ++x) {
              const float got = static_cast<float>(tree.voxel_value(x, y, z));
              if (std::isnan(mean)) {
                EXPECT_TRUE(std::isnan(got)) << x << "," << y << "," << z;
              } else if (uniform) {
                EXPECT_EQ(std::signbit(got), std::signbit(at(x0, y0, z0))) << x << "," << y << "," << z;
                EXPECT_EQ(got, at(x0, y0, z0));
              } else {
                EXPECT_EQ(got, static_cast<float>(mean)) << x << "," << y << "," << z << " level " << level;
                EXPECT_EQ(std::signbit(got), std::signbit(mean)) << x << "," << y << "," << z;
              }
              ++checked;
            }
        cancelling += std::fabs(mean) < 1e19 && r.weight >= 8;
      };
  visit(0, 0, 0, 0);
  EXPECT_GT(checked, voxel_count(dims) / 2);  // most voxels lie in coarse leaves
  EXPECT_GT(cancelling, 200u) << "leaves where 1e20 and -1e20 cancel, and the order decides";
}

TEST(Build, ResultDoesNotDependOnThreads) {
  const Dims dims{70, 50, 90};
  std::mt19937_64 rng(13);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.05, 6);
  BuildOptions one;
  one.threads = 1;
  BuildOptions many;
  many.threads = 5;
  const BuildResult a = build_octree(volume.data(), dims, one);
  const BuildResult b = build_octree(volume.data(), dims, many);
  EXPECT_EQ(a.octree.nodes(), b.octree.nodes());
  EXPECT_EQ(a.octree.value_bytes(), b.octree.value_bytes());
  EXPECT_EQ(a.octree.layout().inner_count, b.octree.layout().inner_count);
}

TEST(Build, RefusesBadArguments) {
  const std::vector<float> volume(8, 0.0f);
  EXPECT_THROW(build_octree(volume.data(), Dims{0, 2, 2}, BuildOptions{}), Error);
  BuildOptions bad;
  bad.value_scale = 0.0;
  EXPECT_THROW(build_octree(volume.data(), Dims{2, 2, 2}, bad), Error);
}

}  // namespace
