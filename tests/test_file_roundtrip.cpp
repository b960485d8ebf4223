// Writing octrees to files and reading them back: every view the Reader gives
// equals the in-memory octree and the source, for each encoding, codec and
// block size; files appear atomically.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

Metadata sample_metadata() {
  Metadata m;
  m.voxel_size = {0.5, 0.25, 2.0};
  m.unit = "mm";
  m.origin = {-10.0, 3.5, 100.0};
  m.quantity = "linear_attenuation";
  m.value_unit = "1/mm";
  m.provenance = default_provenance();
  m.user = {{"operator", "Zoë"}, {"tags", {"bracket", 42}}};
  return m;
}

struct Case {
  Dims dims;
  ValueEncoding encoding;
  std::uint32_t block_bytes;
  bool compress;
  bool byte_planes = true;
  bool framed = true;  // format 1.3 framed blocks; false: format 1.0 .. 1.2
};

class RoundTrip : public ::testing::TestWithParam<Case> {};

TEST_P(RoundTrip, EveryViewMatches) {
  const Case c = GetParam();
  std::mt19937_64 rng(c.dims[0] * 1000 + c.dims[1] * 10 + c.dims[2] + c.block_bytes);
  const std::vector<float> volume = test::random_volume(c.dims, rng, 0.05);
  BuildOptions options;
  options.encoding = c.encoding;
  const Octree tree = build_octree(volume.data(), c.dims, options).octree;
  WriteOptions w;
  w.block_bytes = c.block_bytes;
  w.compress = c.compress;
  w.byte_planes = c.byte_planes;
  w.framed_blocks = c.framed;
  const std::string path = test::temp_path("roundtrip.ivol");
  const Metadata metadata = sample_metadata();
  const WriteStats stats = write_octree(tree, metadata, path, w);
  EXPECT_EQ(stats.file_bytes, std::filesystem::file_size(path));

  Reader reader(path);
  EXPECT_EQ(reader.layout().dims, c.dims);
  EXPECT_EQ(reader.layout().inner_count, tree.layout().inner_count);
  EXPECT_EQ(reader.layout().encoding, c.encoding);
  EXPECT_EQ(reader.metadata().to_json(), metadata.to_json());
  for (unsigned lod = 0; lod <= tree.layout().depth; ++lod)
    ASSERT_EQ(reader.read_lod(lod), tree.read_box(full_box(c.dims, lod), lod)) << "lod " << lod;
  // Stored bits of the whole volume equal the builder's encoding of the source.
  const auto bits = reader.read_box_bits(full_box(c.dims));
  const std::size_t width = encoding_width(c.encoding);
  for (std::size_t i = 0; i < volume.size(); i += 1 + i / 50) {
    std::uint32_t b = 0;
    std::memcpy(&b, bits.data() + i * width, width);
    ASSERT_EQ(b, test::reference_encode(c.encoding, volume[i])) << i;
  }
  const CheckReport report = check_file(path);
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems[0].message);
  EXPECT_TRUE(report.tree_checked);
  // Codec 2 for node words and values, never the metadata, and only when
  // asked; an unframed file that has such a block says version 1.2, an
  // octree file without stays 1.0; a framed file says 1.3, has the 80-byte
  // header and begins with its metadata (spec §15).
  bool planes = false;
  for (const BlockInfo& b : reader.info().blocks) {
    if (b.codec == 2) {
      EXPECT_TRUE(c.byte_planes && c.compress);
      EXPECT_NE(b.stream, static_cast<std::uint8_t>(Stream::Metadata));
      planes = true;
    }
  }
  EXPECT_EQ(reader.info().version_minor, c.framed ? 3 : planes ? 2 : 0);
  EXPECT_EQ(reader.info().framed(), c.framed);
  EXPECT_EQ(reader.info().header_size, c.framed ? 80u : 40u);
  EXPECT_EQ(reader.info().blocks.front().stream == 1, c.framed);
  if (c.compress && c.byte_planes && volume.size() > 64) EXPECT_TRUE(planes);
}

INSTANTIATE_TEST_SUITE_P(Layouts, RoundTrip,
                         ::testing::Values(Case{{1, 1, 1}, ValueEncoding::Binary16, 65536, true},
                                           Case{{3, 5, 7}, ValueEncoding::Float32, 65536, false},
                                           Case{{257, 1, 2}, ValueEncoding::Binary16, 64, true},
                                           Case{{40, 33, 29}, ValueEncoding::Binary16, 256, true},
                                           Case{{40, 33, 29}, ValueEncoding::Float32, 1 << 20, true},
                                           Case{{64, 48, 80}, ValueEncoding::Binary16, 4096, false},
                                           Case{{64, 64, 64}, ValueEncoding::Float32, 8192, true},
                                           Case{{40, 33, 29}, ValueEncoding::Binary16, 4096, true, false},
                                           Case{{64, 64, 64}, ValueEncoding::UInt16, 16384, true},
                                           Case{{40, 33, 29}, ValueEncoding::Binary16, 256, true, true, false},
                                           Case{{40, 33, 29}, ValueEncoding::Float32, 4096, false, true, false},
                                           Case{{3, 5, 7}, ValueEncoding::Binary16, 4096, true, false, false}));

TEST(RoundTrip, UInt16WithScaleAndOffset) {
  const Dims dims{30, 20, 10};
  std::vector<std::uint16_t> volume(voxel_count(dims));
  for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = static_cast<std::uint16_t>((i * 7919) % 65536);
  BuildOptions options;
  options.encoding = ValueEncoding::UInt16;
  options.value_scale = 0.001;
  options.value_offset = -5.0;
  const Octree tree = build_octree(volume.data(), dims, options).octree;
  const std::string path = test::temp_path("u16.ivol");
  write_octree(tree, sample_metadata(), path);
  Reader reader(path);
  EXPECT_EQ(reader.layout().value_scale, 0.001);
  EXPECT_EQ(reader.layout().value_offset, -5.0);
  const auto bits = reader.read_box_bits(full_box(dims));
  for (std::size_t i = 0; i < volume.size(); ++i) {
    std::uint16_t b;
    std::memcpy(&b, bits.data() + 2 * i, 2);
    ASSERT_EQ(b, volume[i]);
  }
  EXPECT_DOUBLE_EQ(reader.voxel_value(3, 2, 1), -5.0 + 0.001 * volume[(1 * 20 + 2) * 30 + 3]);
}

TEST(RoundTrip, TrilinearSampleAtWorldPositions) {
  // A linear ramp is reproduced exactly by trilinear interpolation.
  const Dims dims{9, 7, 5};
  std::vector<float> volume(voxel_count(dims));
  for (std::uint32_t z = 0; z < 5; ++z)
    for (std::uint32_t y = 0; y < 7; ++y)
      for (std::uint32_t x = 0; x < 9; ++x) volume[(z * 7 + y) * 9 + x] = 1.0f * x + 2.0f * y + 4.0f * z;
  BuildOptions options;
  options.encoding = ValueEncoding::Float32;
  const std::string path = test::temp_path("ramp.ivol");
  write_octree(build_octree(volume.data(), dims, options).octree, sample_metadata(), path);
  Reader reader(path);
  const Metadata& m = reader.metadata();
  auto world = [&](double x, double y, double z) {
    return std::array<double, 3>{m.origin[0] + x * m.voxel_size[0], m.origin[1] + y * m.voxel_size[1],
                                 m.origin[2] + z * m.voxel_size[2]};
  };
  for (auto p : {std::array<double, 3>{0, 0, 0}, {3.25, 4.5, 1.75}, {8, 6, 4}, {7.9, 0.1, 3.3}}) {
    const auto w = world(p[0], p[1], p[2]);
    EXPECT_NEAR(reader.sample(w[0], w[1], w[2]), p[0] + 2 * p[1] + 4 * p[2], 1e-9);
  }
  const auto outside = world(-3, 20, 2);  // clamped to (0, 6, 2)
  EXPECT_NEAR(reader.sample(outside[0], outside[1], outside[2]), 0 + 12 + 8, 1e-9);
}

TEST(RoundTrip, ReplacesExistingFileAtomicallyAndLeavesNoTemporary) {
  const Dims dims{8, 8, 8};
  const std::vector<float> a(512, 1.0f);
  const std::vector<float> b(512, 2.0f);
  const std::string dir = test::temp_path("atomic");
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/v.ivol";
  write_octree(build_octree(a.data(), dims, BuildOptions{}).octree, sample_metadata(), path);
  write_octree(build_octree(b.data(), dims, BuildOptions{}).octree, sample_metadata(), path);
  EXPECT_EQ(Reader(path).voxel_value(1, 2, 3), 2.0);
  std::size_t entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) ++entries, (void)e;
  EXPECT_EQ(entries, 1u);
}

TEST(RoundTrip, UnfinishedWriterLeavesNothing) {
  const std::string dir = test::temp_path("unfinished");
  std::filesystem::create_directories(dir);
  {
    VolumeLayout layout;
    layout.dims = {4, 4, 4};
    layout.depth = 2;
    FileWriter writer(dir + "/never.ivol", layout);
    const std::uint16_t value = 0;
    writer.append(encode_block(Stream::Values, 0, 0, 1, 2, &value, WriteOptions{}));
  }  // destroyed without finish()
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

TEST(RoundTrip, WritingIntoMissingDirectoryFailsClearly) {
  const std::vector<float> a(8, 1.0f);
  try {
    write_octree(build_octree(a.data(), Dims{2, 2, 2}, BuildOptions{}).octree, sample_metadata(),
                 "/nonexistent-dir/x.ivol");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::Io);
    EXPECT_NE(std::string(e.what()).find("/nonexistent-dir"), std::string::npos) << e.what();
  }
}

}  // namespace
