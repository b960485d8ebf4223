// Crash safety: a writer killed with SIGKILL at random moments never leaves
// an incomplete file at the target path and never damages the complete file
// it was replacing (temporary file + rename).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/reader.hpp"
#include "ivol/temporary_file.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

// Writes `path` over and over, each time with a different volume whose
// voxel (0, 0, 0) holds the generation number.
[[noreturn]] void write_forever(const std::string& path) {
  const Dims dims{64, 64, 48};
  std::mt19937_64 rng(7);
  std::vector<float> volume = test::random_volume(dims, rng, 0.1, 6);
  WriteOptions options;
  options.block_bytes = 4096;
  for (int generation = 1;; ++generation) {
    volume[0] = static_cast<float>(generation);
    BuildOptions build;
    build.encoding = ValueEncoding::Float32;
    write_octree(build_octree(volume.data(), dims, build).octree, Metadata{}, path, options);
  }
}

TEST(CrashSafety, KilledWritersLeaveOnlyCompleteFiles) {
  const std::string dir = test::temp_path("crash");
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/volume.ivol";
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> delay_us(0, 60000);
  int complete_seen = 0;
  double last_generation = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) write_forever(path);
    std::this_thread::sleep_for(std::chrono::microseconds(delay_us(rng)));
    kill(child, SIGKILL);
    int status = 0;
    waitpid(child, &status, 0);
    ASSERT_TRUE(WIFSIGNALED(status));
    if (!std::filesystem::exists(path)) {
      ASSERT_EQ(complete_seen, 0) << "trial " << trial << ": the file that was there is gone";
      continue;
    }
    const CheckReport report = check_file(path);
    ASSERT_TRUE(report.ok()) << "trial " << trial << ": " << report.problems[0].message;
    ++complete_seen;
    last_generation = Reader(path).voxel_value(0, 0, 0);
    EXPECT_GE(last_generation, 1.0);
  }
  EXPECT_GT(complete_seen, 50) << "most trials should find a complete file";
  // Killed writers leave their temporary files behind (named
  // .volume.ivol.tmp-*), never anything at the target path.
  std::size_t left = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().filename();
    EXPECT_TRUE(name == "volume.ivol" || name.rfind(".volume.ivol.tmp-", 0) == 0) << name;
    left += name != "volume.ivol";
  }
  // Each writer removed what the writers killed before it left: at most the
  // last one's temporary file remains.
  EXPECT_LE(left, 1U);
  // The next writer of the file removes them all, as nobody holds them.
  const Dims dims{8, 8, 8};
  std::vector<float> volume(512, 1.0F);
  write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, Metadata{}, path, WriteOptions{});
  for (const auto& entry : std::filesystem::directory_iterator(dir)) EXPECT_EQ(entry.path().filename(), "volume.ivol");
  std::filesystem::remove_all(dir);
}

// A temporary file that a live writer holds is never taken for an abandoned one.
TEST(CrashSafety, LiveWritersKeepTheirTemporaryFiles) {
  const std::string dir = test::temp_path("live_temporary");
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/volume.ivol";
  std::string held;
  const int fd = create_locked_temporary(path, held);
  ASSERT_GE(fd, 0);
  std::string abandoned;
  const int other = create_locked_temporary(path, abandoned);
  ::close(other);  // as a killed writer's lock goes with it
  EXPECT_EQ(remove_abandoned_temporaries(path), 1U);
  EXPECT_TRUE(std::filesystem::exists(held));
  EXPECT_FALSE(std::filesystem::exists(abandoned));
  ::close(fd);
  EXPECT_EQ(remove_abandoned_temporaries(path), 1U);
  EXPECT_FALSE(std::filesystem::exists(held));
  std::filesystem::remove_all(dir);
}

// Without -f the command line checks that the output does not exist, then
// works; a file that appears meanwhile (another writer) must survive the
// final rename, and the finished temporary file must not be left behind.
std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(CrashSafety, RefusedReplacementKeepsAFileThatAppearedMeanwhile) {
  const std::string dir = test::temp_path("no_replace");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/out.raw";
  refuse_to_replace(path);
  std::string temp;
  int fd = create_locked_temporary(path, temp);
  ASSERT_EQ(::write(fd, "mine", 4), 4);
  std::ofstream(path, std::ios::binary) << "theirs";  // appears while this writer works
  try {
    rename_into_place(temp, path);
    FAIL() << "replaced a file that appeared meanwhile";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not replaced"), std::string::npos) << e.what();
  }
  ::close(fd);
  EXPECT_EQ(read_text(path), "theirs");
  ::unlink(temp.c_str());  // as the writer's destructor does
  // With nothing there, the protected name is still written.
  std::filesystem::remove(path);
  fd = create_locked_temporary(path, temp);
  ASSERT_EQ(::write(fd, "mine", 4), 4);
  rename_into_place(temp, path);
  ::close(fd);
  EXPECT_EQ(read_text(path), "mine");
  EXPECT_FALSE(std::filesystem::exists(temp));
  std::filesystem::remove_all(dir);
}

}  // namespace
