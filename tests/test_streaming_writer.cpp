// The streaming writer gives the same file, byte for byte, as building the
// whole octree in memory and writing it, whatever the slab thickness.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <random>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/octree_slab_builder.hpp"
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

// Slabs built away from the writer (OctreeSlabBuilder, as another rank does),
// their bytes copied as a message would carry them, give the same file as
// add_slab: with and without keep masks, float32 and uint16 samples, a last
// slab thinner than the others.
struct BuiltCase {
  Dims dims;
  ValueEncoding encoding;
  bool keep;
  bool uint16_samples;
  std::uint32_t slab;
};

class BuiltSlabs : public ::testing::TestWithParam<BuiltCase> {};

TEST_P(BuiltSlabs, SameBytesAsAddSlab) {
  const BuiltCase c = GetParam();
  ASSERT_NE(c.dims[2] % c.slab, 0u) << "the last slab should be thinner";
  std::mt19937_64 rng(c.dims[0] * 13 + c.slab);
  const std::vector<float> volume = test::random_volume(c.dims, rng, 0.05, 5);
  std::vector<std::uint16_t> codes(volume.size());
  for (std::size_t i = 0; i < volume.size(); ++i)
    codes[i] = static_cast<std::uint16_t>(std::max(0.0f, volume[i]) * 1000);
  std::vector<std::uint8_t> keep;
  if (c.keep) keep = threshold_keep_mask(volume.data(), c.dims, 2.0f, 1);
  StreamingOptions options;
  options.build.encoding = c.encoding;
  options.build.threads = 2;
  options.write.block_bytes = 512;
  options.slab_slices = c.slab;
  const std::uint64_t slice = std::uint64_t{c.dims[0]} * c.dims[1];
  const std::uint8_t* mask = c.keep ? keep.data() : nullptr;
  Metadata metadata;
  metadata.user = {{"built", true}};

  const std::string direct_path = test::temp_path("direct.ivol");
  StreamingOctreeWriter direct(direct_path, c.dims, options);
  while (direct.next_slab_count() > 0) {
    const std::uint64_t first = direct.next_slab_first() * slice;
    if (c.uint16_samples)
      direct.add_slab(codes.data() + first, mask ? mask + first : nullptr);
    else
      direct.add_slab(volume.data() + first, mask ? mask + first : nullptr);
  }
  const StreamingResult expected = direct.finish(metadata);

  const OctreeSlabBuilder builder(c.dims, options);
  ASSERT_EQ(builder.slab_count(), (c.dims[2] + c.slab - 1) / c.slab);
  std::vector<std::vector<std::uint8_t>> messages;
  // Built in reverse order, as ranks finish in any order.
  for (std::uint32_t k = builder.slab_count(); k-- > 0;) {
    const std::uint64_t first = builder.slab_first(k) * slice;
    const BuiltSlab built = c.uint16_samples ? builder.build(k, codes.data() + first, mask ? mask + first : nullptr)
                                             : builder.build(k, volume.data() + first, mask ? mask + first : nullptr);
    messages.insert(messages.begin(), built.bytes);
  }
  const std::string built_path = test::temp_path("built.ivol");
  StreamingOctreeWriter writer(built_path, c.dims, options);
  for (const auto& message : messages) writer.add_built_slab(BuiltSlab{message});
  const StreamingResult result = writer.finish(metadata);
  EXPECT_EQ(result.max_abs_error, expected.max_abs_error);
  EXPECT_EQ(result.lossless, expected.lossless);
  EXPECT_EQ(result.kept_voxels, expected.kept_voxels);
  EXPECT_EQ(test::read_bytes(built_path), test::read_bytes(direct_path));
  EXPECT_TRUE(check_file(built_path).ok());
}

INSTANTIATE_TEST_SUITE_P(Slabs, BuiltSlabs,
                         ::testing::Values(BuiltCase{{40, 33, 29}, ValueEncoding::Binary16, false, false, 8},
                                           BuiltCase{{40, 33, 29}, ValueEncoding::Binary16, true, false, 8},
                                           BuiltCase{{40, 33, 29}, ValueEncoding::Float32, true, false, 16},
                                           BuiltCase{{33, 20, 37}, ValueEncoding::UInt16, false, true, 8},
                                           BuiltCase{{33, 20, 37}, ValueEncoding::UInt16, true, true, 4},
                                           BuiltCase{{17, 5, 71}, ValueEncoding::Binary16, true, false, 2},
                                           BuiltCase{{9, 9, 9}, ValueEncoding::Binary16, true, false, 2}));

// A writer refuses a built slab of another layout, out of order, or damaged,
// with an ivol::Error that says so, and leaves nothing behind.
TEST(BuiltSlabs, RefusedWhenTheyDoNotFit) {
  const Dims dims{16, 12, 20};
  std::mt19937_64 rng(5);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.05, 5);
  StreamingOptions options;
  options.slab_slices = 8;
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  const OctreeSlabBuilder builder(dims, options);
  const BuiltSlab first = builder.build(0, volume.data());
  const BuiltSlab second = builder.build(1, volume.data() + 8 * slice);
  StreamingOptions thinner = options;
  thinner.slab_slices = 4;
  const BuiltSlab other_layout = OctreeSlabBuilder(dims, thinner).build(0, volume.data());
  StreamingOptions float32 = options;
  float32.build.encoding = ValueEncoding::Float32;
  const BuiltSlab other_encoding = OctreeSlabBuilder(dims, float32).build(0, volume.data());
  const std::uint8_t keep_all[16 * 12 * 8] = {};
  const BuiltSlab with_mask = builder.build(1, volume.data() + 8 * slice, keep_all);
  EXPECT_THROW(builder.build(3, volume.data()), Error);  // the volume has slabs 0 .. 2

  const std::string path = test::temp_path("refuses.ivol");
  auto message_of = [](const std::function<void()>& f) -> std::string {
    try {
      f();
    } catch (const Error& e) {
      return e.what();
    }
    return "no error";
  };
  {
    StreamingOctreeWriter writer(path, dims, options);
    EXPECT_NE(message_of([&] { writer.add_built_slab(second); }).find("built slab 1 given where slab 0 is expected"),
              std::string::npos);
    EXPECT_NE(message_of([&] { writer.add_built_slab(other_layout); }).find("another layout"), std::string::npos);
    EXPECT_NE(message_of([&] { writer.add_built_slab(other_encoding); }).find("another layout"), std::string::npos);
    BuiltSlab damaged = first;
    damaged.bytes.resize(damaged.bytes.size() - 1);
    EXPECT_NE(message_of([&] { writer.add_built_slab(damaged); }).find("do not hold"), std::string::npos);
    EXPECT_NE(message_of([&] {
                writer.add_built_slab(BuiltSlab{{1, 2, 3}});
              }).find("shorter than its header"),
              std::string::npos);
    writer.add_built_slab(first);
    EXPECT_NE(message_of([&] { writer.add_built_slab(with_mask); }).find("every slab has a keep mask or none"),
              std::string::npos);
    EXPECT_NE(message_of([&] { writer.add_built_slab(first); }).find("built slab 0 given where slab 1 is expected"),
              std::string::npos);
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace

// The writer holds a record and per-level counts for every subtree until
// finish(): (dims / slab)^3 of them. The slab thickness is chosen with that
// index counted (issue 23: at 2048^3, 8-slice slabs meant 16.8 M subtrees and
// 3.4 GB of index beside a 172 MB slab budget). Nothing is written here.
TEST(StreamingWriter, SlabThicknessCountsTheSubtreeIndex) {
  const std::string path = test::temp_path("index-bytes.ivol");
  ivol::StreamingOptions options;
  options.slab_budget_bytes = 171824480;  // the recon's writer share at --memory 2048 and 2048^3
  const ivol::StreamingOctreeWriter big(path, {2048, 2048, 2048}, options);
  // 8 slices: 134 MB of samples and 3.5 GB of index; 32: 537 MB and 71 MB.
  EXPECT_EQ(big.slab_slices(), 32u);
  EXPECT_LT(big.index_bytes(), std::uint64_t{100} << 20);
  // Where the budget holds both, the thickest slab that fits, as before.
  options.slab_budget_bytes = std::uint64_t{512} << 20;
  const ivol::StreamingOctreeWriter small(path, {512, 512, 512}, options);
  EXPECT_EQ(small.slab_slices(), 256u);
  EXPECT_LT(small.slab_slices() * std::uint64_t{512} * 512 * 4 + small.index_bytes(), options.slab_budget_bytes);
  EXPECT_FALSE(std::filesystem::exists(path));
}
