// Random access: boxes, slices and single voxels equal the same part of the
// whole volume, and read only part of the file; a level of detail reads only
// the blocks of its levels.
#include <gtest/gtest.h>

#include <random>

#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "synthetic_volume.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

std::vector<float> crop(const std::vector<float>& dense, const Dims& dims, const Box& box) {
  std::vector<float> out;
  out.reserve(box.voxel_count());
  for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
    for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
      for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x)
        out.push_back(dense[(std::uint64_t{z} * dims[1] + y) * dims[0] + x]);
  return out;
}

class PartialReads : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    synthetic::VolumeSpec spec;
    spec.dims = dims_;
    spec.object = synthetic::Object::PencilHolder;
    source_ = new std::vector<float>(synthetic::make_volume(spec));
    const auto keep = threshold_keep_mask(source_->data(), dims_, 0.025f, 2);
    BuildOptions options;
    options.keep_mask = keep.data();
    path_ = new std::string(test::temp_path("partial.ivol"));
    WriteOptions w;
    w.block_bytes = 16384;
    write_octree(build_octree(source_->data(), dims_, options).octree, Metadata{}, *path_, w);
  }
  static void TearDownTestSuite() {
    delete source_;
    delete path_;
  }
  static constexpr Dims dims_{128, 96, 112};
  static std::vector<float>* source_;
  static std::string* path_;
};

std::vector<float>* PartialReads::source_ = nullptr;
std::string* PartialReads::path_ = nullptr;

TEST_F(PartialReads, BoxesSlicesAndVoxelsEqualTheWhole) {
  Reader reader(*path_);
  const std::vector<float> whole = reader.read_lod(0);
  std::mt19937 rng(17);
  for (int n = 0; n < 60; ++n) {
    Box box;
    for (int a = 0; a < 3; ++a) {
      std::uniform_int_distribution<std::uint32_t> pick(0, dims_[a] - 1);
      std::uint32_t p = pick(rng), q = pick(rng);
      if (p > q) std::swap(p, q);
      box.lo[a] = p;
      box.hi[a] = q + 1;
    }
    ASSERT_EQ(reader.read_box(box), crop(whole, dims_, box)) << box.to_string();
  }
  for (Axis axis : {Axis::X, Axis::Y, Axis::Z})
    for (std::uint32_t index : {0u, 37u, 95u})
      ASSERT_EQ(reader.read_slice(axis, index), crop(whole, dims_, slice_box(dims_, axis, index)));
  for (int n = 0; n < 200; ++n) {
    const std::uint32_t x = rng() % dims_[0], y = rng() % dims_[1], z = rng() % dims_[2];
    ASSERT_EQ(static_cast<float>(reader.voxel_value(x, y, z)), whole[(std::uint64_t{z} * dims_[1] + y) * dims_[0] + x]);
  }
}

TEST_F(PartialReads, LevelsOfDetailOfBoxesEqualTheWholeLevel) {
  Reader reader(*path_);
  for (unsigned lod = 1; lod <= 3; ++lod) {
    const std::vector<float> level = reader.read_lod(lod);
    const Dims d = lod_dims(dims_, lod);
    const Box box{{1, 2, 3}, {d[0] - 1, d[1] / 2, d[2]}};
    EXPECT_EQ(reader.read_box(box, lod), crop(level, d, box));
  }
}

TEST_F(PartialReads, ReadOnlyWhatIsNeeded) {
  Reader reader(*path_);
  const FileInfo& info = reader.info();
  const unsigned depth = reader.layout().depth;
  std::uint64_t coarse_bytes = 0;  // blocks of levels <= D - 3, and the metadata
  for (const BlockInfo& b : info.blocks)
    if (b.level <= depth - 3) coarse_bytes += b.stored_size;

  reader.reset_io_stats();
  reader.read_lod(3);
  EXPECT_LE(reader.io_stats().bytes_read, coarse_bytes);
  EXPECT_LT(reader.io_stats().bytes_read, info.file_size / 20) << "a 1/8 preview reads under 5 % of the file";

  Reader fresh(*path_);
  fresh.reset_io_stats();
  fresh.read_slice(Axis::Z, 56);
  // In a file this small a block spans much of the object; bench/ measures
  // the fractions at 512^3.
  EXPECT_LT(fresh.io_stats().bytes_read, info.file_size / 2);

  Reader third(*path_);
  third.reset_io_stats();
  third.read_box(Box{{10, 10, 10}, {42, 42, 42}});
  EXPECT_LT(third.io_stats().bytes_read, info.file_size / 2);
}

TEST_F(PartialReads, RefusesBoxesOutsideTheVolume) {
  Reader reader(*path_);
  EXPECT_THROW(reader.read_box(Box{{0, 0, 0}, {129, 1, 1}}), Error);
  EXPECT_THROW(reader.read_box(Box{{5, 0, 0}, {5, 1, 1}}), Error);
  EXPECT_THROW(reader.read_lod(reader.layout().depth + 1), Error);
  EXPECT_THROW(reader.voxel_value(0, 96, 0), Error);
}

}  // namespace
