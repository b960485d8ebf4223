// The streaming octree writer's temporary spill file: compressed (at most
// 1.2x the finished file for noisy lossless and for coarsened volumes, the
// file itself still identical to the in-memory writer's), placed where asked
// (option, then TMPDIR, then the output's directory), never visible by name,
// and gone when the writer is killed.
#include <dirent.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <random>

#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

// 16-bit CT-like values: two nested balls in air, Gaussian noise of sigma 20
// on every voxel (no two leaves merge).
std::vector<std::uint16_t> noisy_balls(const Dims& dims) {
  std::mt19937_64 rng(23);
  std::normal_distribution<double> noise(0.0, 20.0);
  std::vector<std::uint16_t> v(voxel_count(dims));
  const double c = (dims[0] - 1) / 2.0;
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x, ++i) {
        const double r = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c));
        const double base = r > 0.4 * dims[0] ? 300 : r > 0.2 * dims[0] ? 2000 : 3500;
        v[i] = static_cast<std::uint16_t>(std::lround(base + noise(rng)));
      }
  return v;
}

std::size_t entries_in(const std::string& directory) {
  std::size_t n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(directory)) {
    (void)entry;
    ++n;
  }
  return n;
}

struct Streamed {
  StreamingResult result;
  std::string path;
};

Streamed stream(const std::vector<std::uint16_t>& volume, const Dims& dims, const std::uint8_t* keep,
                const std::string& name, const std::string& spill_directory = {}) {
  StreamingOptions options;
  options.build.encoding = ValueEncoding::UInt16;
  options.slab_slices = 16;
  options.spill_directory = spill_directory;
  Streamed out{{}, test::temp_path(name)};
  StreamingOctreeWriter writer(out.path, dims, options);
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  while (writer.next_slab_count() > 0) {
    const std::uint64_t first = writer.next_slab_first() * slice;
    writer.add_slab(volume.data() + first, keep ? keep + first : nullptr);
  }
  out.result = writer.finish(Metadata{});
  return out;
}

class SpillSize : public ::testing::TestWithParam<bool> {};

// The spill holds every subtree; compressed, it stays within 1.2x the file.
TEST_P(SpillSize, AtMostOnePointTwoTimesTheFile) {
  const bool coarsened = GetParam();
  const Dims dims{96, 96, 96};
  const std::vector<std::uint16_t> volume = noisy_balls(dims);
  std::vector<float> as_float(volume.begin(), volume.end());
  std::vector<std::uint8_t> keep;
  if (coarsened) keep = threshold_keep_mask(as_float.data(), dims, 1000.0f, 2);
  const Streamed s = stream(volume, dims, coarsened ? keep.data() : nullptr, "spilled.ivol");
  // The reference: the whole octree built in memory and written.
  BuildOptions build;
  build.encoding = ValueEncoding::UInt16;
  build.keep_mask = coarsened ? keep.data() : nullptr;
  const std::string expected = test::temp_path("in-memory.ivol");
  write_octree(build_octree(volume.data(), dims, build).octree, Metadata{}, expected);
  EXPECT_EQ(test::read_bytes(s.path), test::read_bytes(expected));
  EXPECT_EQ(s.result.lossless, !coarsened);
  const double file = static_cast<double>(s.result.write.file_bytes);
  EXPECT_GT(s.result.spill_bytes, 0u);
  EXPECT_LE(static_cast<double>(s.result.spill_bytes), 1.2 * file)
      << s.result.spill_bytes << " spill bytes for a file of " << file;
  // Uncompressed it held at least the leaves' values: 2 bytes per kept voxel.
  EXPECT_LT(s.result.spill_bytes, 2 * s.result.kept_voxels);
}

INSTANTIATE_TEST_SUITE_P(LosslessAndCoarsened, SpillSize, ::testing::Values(false, true));

// The option wins over TMPDIR, which wins over the output's directory.
TEST(SpillPlacement, OptionThenTmpdirThenOutputDirectory) {
  const std::string option = test::temp_path("option"), tmpdir = test::temp_path("tmpdir");
  std::filesystem::create_directories(option);
  std::filesystem::create_directories(tmpdir);
  const std::string output = test::temp_path("out.ivol");
  const char* saved = std::getenv("TMPDIR");
  const std::string saved_value = saved ? saved : "";
  ::setenv("TMPDIR", tmpdir.c_str(), 1);
  EXPECT_EQ(spill_directory_for(output, option), option);
  EXPECT_EQ(spill_directory_for(output, ""), tmpdir);
  ::setenv("TMPDIR", "", 1);
  EXPECT_EQ(spill_directory_for(output, ""), test::temp_dir());
  ::unsetenv("TMPDIR");
  EXPECT_EQ(spill_directory_for(output, ""), test::temp_dir());
  EXPECT_EQ(spill_directory_for("relative.ivol", ""), ".");

  const Dims dims{32, 32, 32};
  const std::vector<std::uint16_t> volume = noisy_balls(dims);
  ::setenv("TMPDIR", tmpdir.c_str(), 1);
  EXPECT_EQ(stream(volume, dims, nullptr, "a.ivol").result.spill_directory, tmpdir);
  EXPECT_EQ(stream(volume, dims, nullptr, "b.ivol", option).result.spill_directory, option);
  if (saved)
    ::setenv("TMPDIR", saved_value.c_str(), 1);
  else
    ::unsetenv("TMPDIR");
  EXPECT_EQ(entries_in(option), 0u);
  EXPECT_EQ(entries_in(tmpdir), 0u);
}

// A spill directory that cannot be used is refused when the writer is made,
// naming it; nothing is written.
TEST(SpillPlacement, MissingDirectoryRefusedFirst) {
  const std::string missing = test::temp_path("no-such-dir");
  const std::string output = test::temp_path("never.ivol");
  StreamingOptions options;
  options.spill_directory = missing;
  try {
    StreamingOctreeWriter writer(output, Dims{16, 16, 16}, options);
    FAIL() << "a missing spill directory was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(output));
}

// While the writer runs its spill file has no name; killed, it leaves nothing.
TEST(SpillPlacement, KilledWriterLeavesNothingInTheSpillDirectory) {
  const std::string spill = test::temp_path("spill");
  std::filesystem::create_directories(spill);
  const Dims dims{64, 64, 64};
  const std::vector<std::uint16_t> volume = noisy_balls(dims);
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    StreamingOptions options;
    options.build.encoding = ValueEncoding::UInt16;
    options.slab_slices = 16;
    options.spill_directory = spill;
    StreamingOctreeWriter writer(test::temp_path("killed.ivol"), dims, options);
    writer.add_slab(volume.data());
    writer.add_slab(volume.data() + 16 * 64 * 64);
    const char byte = 1;
    if (::write(ready[1], &byte, 1) != 1) std::_Exit(2);
    for (;;) ::pause();
  }
  ::close(ready[1]);
  char byte = 0;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1);
  ::close(ready[0]);
  // The child holds a file in the spill directory that the directory does not list.
  bool holds_spill = false;
  const std::string fds = "/proc/" + std::to_string(child) + "/fd";
  for (const auto& fd : std::filesystem::directory_iterator(fds)) {
    std::error_code ec;
    const std::string target = std::filesystem::read_symlink(fd.path(), ec).string();
    if (!ec && target.rfind(spill + "/", 0) == 0 && target.find("(deleted)") != std::string::npos) {
      holds_spill = true;
      EXPECT_GT(std::filesystem::file_size(fd.path()), 0u);  // through /proc: the data is there
    }
  }
  EXPECT_TRUE(holds_spill);
  EXPECT_EQ(entries_in(spill), 0u);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(entries_in(spill), 0u);
}

}  // namespace
