// The four structures: they tile the volume, keep full resolution where the
// need mask says, convert to and from dense, write as .ivol, and cost the
// memory the paper's arithmetic predicts.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/structures.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

NeedMask random_mask(const Dims& dims, std::uint32_t factor, std::mt19937_64& rng, double density) {
  NeedMask m;
  m.dims = dims;
  m.factor = factor;
  m.cells = {(dims[0] + factor - 1) / factor, (dims[1] + factor - 1) / factor, (dims[2] + factor - 1) / factor};
  m.need.resize(voxel_count(m.cells));
  // A blob of needed cells plus scattered ones.
  std::bernoulli_distribution scatter(density);
  for (std::uint32_t k = 0; k < m.cells[2]; ++k)
    for (std::uint32_t j = 0; j < m.cells[1]; ++j)
      for (std::uint32_t i = 0; i < m.cells[0]; ++i) {
        const double dx = i - m.cells[0] / 2.0, dy = j - m.cells[1] / 3.0, dz = k - m.cells[2] / 2.0;
        m.need[(std::uint64_t{k} * m.cells[1] + j) * m.cells[0] + i] =
            (dx * dx + dy * dy + dz * dz < m.cells[0] * m.cells[0] / 16.0) || scatter(rng);
      }
  return m;
}

const StructureKind kAll[] = {StructureKind::Regular, StructureKind::Rectilinear, StructureKind::Nested,
                              StructureKind::Octree};

struct Case {
  Dims dims;
  std::uint32_t factor;
};

class Structures : public ::testing::TestWithParam<Case> {};

TEST_P(Structures, TileTheVolumeAndKeepFullResolutionWhereNeeded) {
  const Case c = GetParam();
  std::mt19937_64 rng(c.dims[0] + 31 * c.factor);
  const NeedMask mask = random_mask(c.dims, c.factor, rng, 0.02);
  for (StructureKind kind : kAll) {
    SCOPED_TRACE(structure_name(kind));
    GenerationOptions options;
    options.nested_cell = 8;
    options.rectilinear_max_interval = 16;
    const auto s = generate_structure(kind, mask, options);
    std::vector<std::uint8_t> covered(voxel_count(c.dims), 0);
    std::vector<std::uint8_t> fine(voxel_count(c.dims), 0);
    std::uint64_t values = 0;
    for (const Brick& b : s->bricks()) {
      EXPECT_EQ(b.first_value, values);
      values += b.voxel_count();
      const bool is_fine = b.voxel == std::array<std::uint32_t, 3>{1, 1, 1};
      for (std::uint64_t z = b.origin[2];
           z < std::min<std::uint64_t>(c.dims[2], b.origin[2] + std::uint64_t{b.voxel[2]} * b.count[2]); ++z)
        for (std::uint64_t y = b.origin[1];
             y < std::min<std::uint64_t>(c.dims[1], b.origin[1] + std::uint64_t{b.voxel[1]} * b.count[1]); ++y)
          for (std::uint64_t x = b.origin[0];
               x < std::min<std::uint64_t>(c.dims[0], b.origin[0] + std::uint64_t{b.voxel[0]} * b.count[0]); ++x) {
            const std::uint64_t at = (z * c.dims[1] + y) * c.dims[0] + x;
            ++covered[at];
            fine[at] = is_fine;
          }
    }
    EXPECT_EQ(values, s->voxel_count());
    for (std::uint32_t z = 0; z < c.dims[2]; ++z)
      for (std::uint32_t y = 0; y < c.dims[1]; ++y)
        for (std::uint32_t x = 0; x < c.dims[0]; ++x) {
          const std::uint64_t at = (std::uint64_t{z} * c.dims[1] + y) * c.dims[0] + x;
          ASSERT_EQ(covered[at], 1) << "voxel " << x << "," << y << "," << z << " covered " << int(covered[at])
                                    << " times";
          if (mask.at(x / c.factor, y / c.factor, z / c.factor)) ASSERT_TRUE(fine[at]) << x << "," << y << "," << z;
        }
    // Scattered needs can refine every plane of the rectilinear grid and
    // every cell of the nested grid (the paper's point about their limits);
    // the octree always coarsens what is not needed.
    if (kind == StructureKind::Octree)
      EXPECT_LT(s->voxel_count(), voxel_count(c.dims));
    else
      EXPECT_LE(s->voxel_count(), voxel_count(c.dims));
  }
}

TEST_P(Structures, DenseRoundTripAndLookup) {
  const Case c = GetParam();
  std::mt19937_64 rng(c.dims[1] + c.factor);
  const NeedMask mask = random_mask(c.dims, c.factor, rng, 0.01);
  std::vector<float> dense(voxel_count(c.dims));
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (auto& v : dense) v = unit(rng);
  for (StructureKind kind : kAll) {
    SCOPED_TRACE(structure_name(kind));
    const auto s = generate_structure(kind, mask);
    s->sample_dense(dense.data());
    std::vector<float> back(dense.size());
    s->to_dense(back.data());
    for (std::uint32_t z = 0; z < c.dims[2]; z += 3)
      for (std::uint32_t y = 0; y < c.dims[1]; y += 2)
        for (std::uint32_t x = 0; x < c.dims[0]; ++x) {
          const std::uint64_t at = (std::uint64_t{z} * c.dims[1] + y) * c.dims[0] + x;
          ASSERT_EQ(back[at], s->values()[s->value_index(x, y, z)]);
          if (mask.at(x / c.factor, y / c.factor, z / c.factor)) ASSERT_EQ(back[at], dense[at]);
        }
  }
}

INSTANTIATE_TEST_SUITE_P(Shapes, Structures,
                         ::testing::Values(Case{{32, 32, 32}, 1}, Case{{64, 48, 40}, 4}, Case{{37, 21, 50}, 2},
                                           Case{{100, 9, 33}, 8}));

TEST(StructureMemory, FullyRefinedOctreeAndRegularGrid) {
  // Everything needed: the octree is fully refined. Nodes (N^3 - 1) / 7,
  // values 1 + 8 nodes: 24/7 = 3.43 bytes per voxel with 16-bit values (the
  // paper's 5.71 counts 4-byte values); a regular grid costs 2 bytes.
  NeedMask m;
  m.dims = {64, 64, 64};
  m.factor = 4;
  m.cells = {16, 16, 16};
  m.need.assign(4096, 1);
  const auto octree = generate_structure(StructureKind::Octree, m);
  const std::uint64_t voxels = 64 * 64 * 64;
  const std::uint64_t inner = (voxels - 1) / 7;
  EXPECT_EQ(octree->memory().structure_bytes, 8 * inner);
  EXPECT_EQ(octree->memory().value_bytes, 2 * (1 + 8 * inner));
  EXPECT_NEAR(static_cast<double>(octree->memory().total()) / voxels, 24.0 / 7.0, 1e-4);
  EXPECT_EQ(octree->voxel_count(), voxels);
  const auto regular = generate_structure(StructureKind::Regular, m);
  EXPECT_EQ(regular->memory().total(), 2 * voxels);
}

TEST(StructureWriter, OctreeFileHasTheGeneratedStructureAndValues) {
  const Dims dims{50, 40, 30};
  std::mt19937_64 rng(3);
  const NeedMask mask = random_mask(dims, 2, rng, 0.01);
  std::vector<float> dense(voxel_count(dims));
  for (std::size_t i = 0; i < dense.size(); ++i) dense[i] = static_cast<float>(i % 1000) * 0.25f;
  for (StructureKind kind : kAll) {
    SCOPED_TRACE(structure_name(kind));
    const auto s = generate_structure(kind, mask);
    s->sample_dense(dense.data());
    StreamingOptions options;
    options.build.encoding = ValueEncoding::Float32;
    options.slab_slices = 8;
    const std::string path = test::temp_path(std::string(structure_name(kind)) + ".ivol");
    write_structure(*s, path, Metadata{}, options);
    Reader reader(path);
    EXPECT_EQ(reader.layout().kind, kind) << "written in its own form";
    // Framed blocks (the default) need format 1.3, which has codec 2 too.
    EXPECT_EQ(reader.info().version_minor, 3);
    EXPECT_TRUE(reader.info().framed());
    std::vector<float> expected(dense.size());
    s->to_dense(expected.data());
    EXPECT_EQ(reader.read_lod(0), expected);
    const CheckReport report = check_file(path);
    EXPECT_TRUE(report.ok()) << report.problems.at(0).message;
    if (kind == StructureKind::Octree)
      EXPECT_EQ(reader.layout().total_inner() * 8, s->memory().structure_bytes) << "the file is the generated octree";
    // Levels of detail: the box filter of the dense volume (spec §12.3).
    std::vector<std::uint32_t> bits(expected.size());
    for (std::size_t i = 0; i < bits.size(); ++i) bits[i] = test::reference_encode(ValueEncoding::Float32, expected[i]);
    for (unsigned lod = 1; lod <= 2; ++lod) {
      const auto reference = test::reference_lod(bits, dims, ValueEncoding::Float32, lod);
      const auto got = reader.read_box_bits(full_box(dims, lod), lod);
      ASSERT_EQ(got.size(), reference.size() * 4);
      for (std::size_t i = 0; i < reference.size(); ++i) {
        std::uint32_t g;
        std::memcpy(&g, got.data() + 4 * i, 4);
        ASSERT_LE(test::ulp_distance(ValueEncoding::Float32, g, reference[i]), 1u) << "lod " << lod << " at " << i;
      }
    }
    // Voxel, box and slice reads agree with the whole.
    const Box box{{3, 5, 7}, {41, 22, 30}};
    const auto part = reader.read_box(box);
    std::size_t n = 0;
    for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
      for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
        for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x)
          ASSERT_EQ(part[n++], expected[(std::uint64_t{z} * dims[1] + y) * dims[0] + x]);
    EXPECT_EQ(reader.voxel_value(49, 39, 29), expected.back());
  }
}

TEST(Generation, SameStructureWithAnyThreadCount) {
  const Dims dims{120, 80, 96};
  std::mt19937_64 rng(8);
  const NeedMask mask = random_mask(dims, 4, rng, 0.03);
  GenerationOptions one, many;
  one.threads = 1;
  many.threads = 6;
  const auto a = generate_structure(StructureKind::Octree, mask, one);
  const auto b = generate_structure(StructureKind::Octree, mask, many);
  ASSERT_EQ(a->bricks().size(), b->bricks().size());
  for (std::size_t n = 0; n < a->bricks().size(); ++n) {
    EXPECT_EQ(a->bricks()[n].origin, b->bricks()[n].origin);
    EXPECT_EQ(a->bricks()[n].count, b->bricks()[n].count);
  }
  EXPECT_EQ(a->memory().total(), b->memory().total());
}

}  // namespace

namespace {

// A brick given field by field comes back field by field, whether it is
// packed as a clipped cube or through the shape table; 16 bytes a brick
// (issue 23: 48 before).
TEST(BrickList, EveryBrickComesBackAsGiven) {
  const Dims dims{96, 90, 77};
  BrickList list(dims);
  std::vector<Brick> given;
  std::mt19937_64 rng(23);
  for (int n = 0; n < 4000; ++n) {
    Brick b;
    for (int a = 0; a < 3; ++a) b.origin[a] = static_cast<std::uint32_t>(rng() % dims[a]);
    const unsigned kind = rng() % 3;
    const std::uint32_t side = 1U << (rng() % 7);
    for (int a = 0; a < 3; ++a) {
      const std::uint32_t extent = std::min(side, dims[a] - b.origin[a]);
      const std::uint32_t any = 1 + static_cast<std::uint32_t>(rng() % 5);
      b.voxel[a] = kind == 0 ? 1 : kind == 1 ? extent : any;  // fine cube, coarse cube, anything
      b.count[a] = kind == 0 ? extent : kind == 1 ? 1 : 1 + static_cast<std::uint32_t>(rng() % 9);
    }
    list.push_back(b);
    given.push_back(b);
  }
  const std::uint64_t total = list.assign_first_values();
  ASSERT_EQ(list.size(), given.size());
  std::uint64_t next = 0;
  for (std::size_t n = 0; n < given.size(); ++n) {
    const Brick b = list[n];
    EXPECT_EQ(b.origin, given[n].origin) << n;
    EXPECT_EQ(b.voxel, given[n].voxel) << n;
    EXPECT_EQ(b.count, given[n].count) << n;
    EXPECT_EQ(b.first_value, next) << n;
    next += given[n].voxel_count();
  }
  EXPECT_EQ(total, next);
}

TEST(BrickList, AnOctreeTakesSixteenBytesABrick) {
  std::mt19937_64 rng(5);
  const NeedMask mask = random_mask({96, 90, 77}, 4, rng, 0.05);
  const auto octree = generate_structure(StructureKind::Octree, mask);
  ASSERT_GT(octree->bricks().size(), 1000U);
  EXPECT_EQ(octree->bricks().memory_bytes(), 16 * octree->bricks().size());
}

TEST(BrickList, RefusesAxesLongerThanTheOriginBits) {
  EXPECT_THROW(BrickList({(1U << 21) + 1, 4, 4}), Error);
  EXPECT_THROW(BrickList({4, 4, (1U << 21) + 1}), Error);
  EXPECT_NO_THROW(BrickList({1U << 21, 1U << 21, 1U << 21}));
}

}  // namespace
