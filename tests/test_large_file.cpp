// Files above 4 GiB: block offsets and sizes beyond 32 bits are written and
// read back. Needs about 10 GiB free next to the test's temporary files (the
// file, and the streaming writer's spill file while it builds) and runs in
// the normal build only (under the sanitizers it would take many minutes);
// otherwise it says why it was skipped.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>

#include "ivol/check.hpp"
#include "ivol/reader.hpp"
#include "ivol/streaming_writer.hpp"

namespace {

using namespace ivol;

// Noise that does not compress and that the test can recompute anywhere.
float value_at(std::uint64_t index) {
  std::uint64_t x = index * 0x9E3779B97F4A7C15ULL;
  x ^= x >> 29;
  x *= 0xBF58476D1CE4E5B9ULL;
  x ^= x >> 32;
  return static_cast<float>(x & 0xFFFFFF) / 16777216.0F;
}

TEST(LargeFile, OffsetsBeyond32BitsRoundTrip) {
#ifdef IVOL_SANITIZED_BUILD
  GTEST_SKIP() << "skipped in the sanitizer build (4.3 GiB through ASan takes too long); the normal build runs it";
#endif
  const std::filesystem::path dir = std::filesystem::temp_directory_path();
  const std::uint64_t free_bytes = std::filesystem::space(dir).available;
  if (free_bytes < (10ULL << 30))
    GTEST_SKIP() << "skipped: needs 10 GiB free in " << dir << ", has " << (free_bytes >> 20) << " MiB";
  const std::string path = (dir / "ivol_large_file_test.ivol").string();
  const Dims dims{1024, 1024, 1040};  // 4.06 GiB of float32 values, one leaf each
  StreamingOptions options;
  options.build.encoding = ValueEncoding::Float32;
  options.write.compress = false;  // stored blocks: the file is as large as its data
  options.write.block_bytes = 1 << 20;
  options.slab_slices = 16;
  {
    StreamingOctreeWriter writer(path, dims, options);
    std::vector<float> slab;
    while (writer.next_slab_count() > 0) {
      const std::uint64_t first = std::uint64_t{writer.next_slab_first()} * dims[0] * dims[1];
      slab.resize(std::uint64_t{writer.next_slab_count()} * dims[0] * dims[1]);
      for (std::uint64_t i = 0; i < slab.size(); ++i) slab[i] = value_at(first + i);
      writer.add_slab(slab.data());
    }
    const StreamingResult result = writer.finish(Metadata{});
    EXPECT_GT(result.write.file_bytes, 4ULL << 30);
    std::printf("wrote %.2f GiB\n", static_cast<double>(result.write.file_bytes) / (1 << 30));
  }
  ASSERT_GT(std::filesystem::file_size(path), 4ULL << 30);
  {
    Reader reader(path);
    // Voxels whose values lie past 4 GiB in the file, and a few before.
    for (const std::array<std::uint32_t, 3> v :
         {std::array<std::uint32_t, 3>{0, 0, 0}, {1023, 1023, 1039}, {512, 7, 1030}, {3, 1000, 990}, {700, 300, 520}}) {
      const std::uint64_t index = (std::uint64_t{v[2]} * dims[1] + v[1]) * dims[0] + v[0];
      EXPECT_EQ(reader.voxel_value(v[0], v[1], v[2]), value_at(index)) << v[0] << "," << v[1] << "," << v[2];
    }
    const std::vector<float> last = reader.read_box(Box{{0, 0, 1039}, {1024, 1024, 1040}});
    const std::uint64_t first = std::uint64_t{1039} * dims[0] * dims[1];
    for (std::uint64_t i = 0; i < last.size(); i += 997) ASSERT_EQ(last[i], value_at(first + i));
  }
  const CheckReport report = check_file(path);
  EXPECT_TRUE(report.ok()) << (report.problems.empty() ? "" : report.problems.front().message);
  EXPECT_TRUE(report.tree_checked);
  std::filesystem::remove(path);
}

}  // namespace
