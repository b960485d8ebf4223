// The streaming writer gives the same file, byte for byte, as building the
// whole octree in memory and writing it, whatever the slab thickness.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

struct Case {
  Dims dims;
  ValueEncoding encoding;
  bool keep;
  std::uint32_t slab;
};

class Streaming : public ::testing::TestWithParam<Case> {};

TEST_P(Streaming, SameBytesAsInMemory) {
  const Case c = GetParam();
  std::mt19937_64 rng(c.dims[0] * 7 + c.dims[2] + c.slab);
  const std::vector<float> volume = test::random_volume(c.dims, rng, 0.05, 5);
  std::vector<std::uint8_t> keep;
  if (c.keep) keep = threshold_keep_mask(volume.data(), c.dims, 2.0f, 1);
  Metadata metadata;
  metadata.user = {{"case", c.slab}};

  BuildOptions build;
  build.encoding = c.encoding;
  if (c.encoding == ValueEncoding::UInt16) build.value_scale = 1.0 / 256;
  WriteOptions write;
  write.block_bytes = 512;
  BuildOptions in_memory = build;
  in_memory.keep_mask = c.keep ? keep.data() : nullptr;
  const BuildResult built = build_octree(volume.data(), c.dims, in_memory);
  const std::string expected_path = test::temp_path("in-memory.ivol");
  write_octree(built.octree, metadata, expected_path, write);

  StreamingOptions options;
  options.build = build;
  options.write = write;
  options.slab_slices = c.slab;
  const std::string path = test::temp_path("streamed.ivol");
  StreamingOctreeWriter writer(path, c.dims, options);
  const std::uint64_t slice = std::uint64_t{c.dims[0]} * c.dims[1];
  while (writer.next_slab_count() > 0) {
    const std::uint64_t first = writer.next_slab_first() * slice;
    writer.add_slab(volume.data() + first, c.keep ? keep.data() + first : nullptr);
  }
  const StreamingResult result = writer.finish(metadata);
  EXPECT_EQ(result.max_abs_error, built.max_abs_error);
  EXPECT_EQ(result.lossless, built.lossless);
  EXPECT_EQ(result.kept_voxels, built.kept_voxels);
  EXPECT_EQ(test::read_bytes(path), test::read_bytes(expected_path));
  EXPECT_TRUE(check_file(path).ok());
}

INSTANTIATE_TEST_SUITE_P(Slabs, Streaming,
                         ::testing::Values(Case{{40, 33, 29}, ValueEncoding::Binary16, false, 8},
                                           Case{{40, 33, 29}, ValueEncoding::Binary16, true, 8},
                                           Case{{40, 33, 29}, ValueEncoding::Float32, true, 16},
                                           Case{{64, 64, 64}, ValueEncoding::Binary16, true, 1},
                                           Case{{64, 64, 64}, ValueEncoding::UInt16, false, 32},
                                           Case{{17, 5, 70}, ValueEncoding::Binary16, true, 4},
                                           Case{{3, 5, 7}, ValueEncoding::Float32, false, 2},
                                           Case{{1, 1, 1}, ValueEncoding::Binary16, false, 0},
                                           Case{{30, 30, 30}, ValueEncoding::Binary16, true, 64}));

TEST(StreamingWriter, UInt16SlabsAndMisuse) {
  const Dims dims{20, 10, 12};
  std::vector<std::uint16_t> volume(voxel_count(dims));
  for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = static_cast<std::uint16_t>((i / 7) % 50 * 1000);
  BuildOptions build;
  build.encoding = ValueEncoding::UInt16;
  StreamingOptions options;
  options.build = build;
  options.slab_slices = 8;
  const std::string path = test::temp_path("u16-stream.ivol");
  {
    StreamingOctreeWriter writer(path, dims, options);
    EXPECT_THROW(writer.finish(Metadata{}), Error);  // no slab yet
    writer.add_slab(volume.data());
    const float f = 0;
    EXPECT_THROW(writer.add_slab(&f), Error);        // another sample type
    EXPECT_THROW(writer.finish(Metadata{}), Error);  // one slab missing
  }
  EXPECT_FALSE(std::filesystem::exists(path));  // nothing left behind
  StreamingOctreeWriter writer(path, dims, options);
  writer.add_slab(volume.data());
  writer.add_slab(volume.data() + 8 * 200);
  EXPECT_TRUE(writer.finish(Metadata{}).lossless);
  BuildOptions in_memory = build;
  const std::string expected = test::temp_path("u16-memory.ivol");
  write_octree(build_octree(volume.data(), dims, in_memory).octree, Metadata{}, expected);
  EXPECT_EQ(test::read_bytes(path), test::read_bytes(expected));
}

}  // namespace
