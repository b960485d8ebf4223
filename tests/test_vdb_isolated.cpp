// The OpenVDB reader the converters use (open_vdb_slabs, libopenvdb in a
// child process, tools/isolated/vdb_isolated.cpp): values and geometry as
// OpenVDB's own accessor and transform give them, a damaged file's huge
// allocation refused in the child and never made here, a crash of the child
// an error naming the file.
#include <dirent.h>
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <sys/resource.h>
#include <unistd.h>

#include <csignal>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "expect_error.hpp"
#include "ivol/error.hpp"
#include "test_support.hpp"
#include "vdb_io.hpp"

namespace ivol::convert {
namespace {

using test::contains;
using test::error_of;

// A grid with a scale, a translation and metadata, written by libopenvdb.
std::string write_grid(const std::string& name, openvdb::FloatGrid::Ptr* kept = nullptr) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(-0.5f);
  grid->setName("temperature");
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
  grid->transform().postTranslate(openvdb::Vec3d(1.0, -2.0, 3.5));
  grid->insertMeta("quantity", openvdb::StringMetadata("temperature"));
  grid->insertMeta("value_unit", openvdb::StringMetadata("K"));
  openvdb::FloatGrid::Accessor accessor = grid->getAccessor();
  for (int z = -3; z < 4; ++z)
    for (int y = 5; y < 9; ++y)
      for (int x = 10; x < 15; ++x)
        if ((x + y + z) % 3 != 0) accessor.setValue(openvdb::Coord(x, y, z), float(x * 100 + y * 10 + z) / 7.0f);
  const std::string path = test::temp_path(name);
  openvdb::io::File file(path);
  file.write({grid});
  file.close();
  if (kept) *kept = grid;
  return path;
}

TEST(VdbIsolated, SlabsHoldWhatOpenVdbsAccessorGives) {
  openvdb::FloatGrid::Ptr grid;
  const std::string path = write_grid("isolated.vdb", &grid);
  VdbSourceInfo source;
  const auto reader = open_vdb_slabs(path, "", &source);
  const DenseVolume& shape = reader->shape();
  ASSERT_EQ(shape.dims, (Dims{5, 4, 7}));
  ASSERT_EQ(shape.type, SampleType::Float32);
  EXPECT_EQ(source.grid_name, "temperature");
  EXPECT_EQ(source.background, -0.5f);
  EXPECT_EQ(source.was_half, grid->saveFloatAsHalf());
  // The world position of index (10, 5, -3), the box's first voxel.
  EXPECT_TRUE(shape.has_geometry);
  EXPECT_EQ(shape.voxel_size, (std::array<double, 3>{0.25, 0.25, 0.25}));
  EXPECT_EQ(shape.origin, (std::array<double, 3>{1.0 + 2.5, -2.0 + 1.25, 3.5 - 0.75}));
  EXPECT_EQ(shape.quantity, "temperature");
  EXPECT_EQ(shape.value_unit, "K");
  // Two slabs, as a converter reads them.
  std::vector<float> values(std::size_t{5} * 4 * 7);
  reader->read(0, 3, values.data());
  reader->read(3, 4, values.data() + 5 * 4 * 3);
  const openvdb::FloatGrid::ConstAccessor accessor = grid->getConstAccessor();
  std::size_t i = 0;
  for (int z = -3; z < 4; ++z)
    for (int y = 5; y < 9; ++y)
      for (int x = 10; x < 15; ++x, ++i)
        ASSERT_EQ(values[i], accessor.getValue(openvdb::Coord(x, y, z))) << x << "," << y << "," << z;
}

TEST(VdbIsolated, ErrorsComeBackWithTheirClass) {
  const std::string path = write_grid("isolated-errors.vdb");
  const Error missing = error_of([&] { open_vdb_slabs(path, "pressure"); });
  EXPECT_EQ(missing.error_class(), ErrorClass::InvalidArgument);
  EXPECT_TRUE(contains(missing.what(), "'pressure'")) << missing.what();
  EXPECT_TRUE(contains(missing.what(), "'temperature'")) << missing.what();
  // A box beyond the budget (96 MiB held densely, 32 MiB given; the grid
  // itself is two leaves): refused by the child's read_vdb, as in process.
  auto wide = openvdb::FloatGrid::create(0.0f);
  wide->setName("wide");
  wide->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
  wide->tree().setValue(openvdb::Coord(1 << 24, 0, 0), 2.0f);
  const std::string wide_path = test::temp_path("isolated-wide.vdb");
  openvdb::io::File file(wide_path);
  file.write({wide});
  file.close();
  const Error budget = error_of([&] { open_vdb_slabs(wide_path, "", nullptr, std::uint64_t{32} << 20); });
  EXPECT_EQ(budget.error_class(), ErrorClass::LimitExceeded);
  EXPECT_TRUE(contains(budget.what(), wide_path + ": grid 'wide'")) << budget.what();
  EXPECT_TRUE(contains(budget.what(), "16777217x1x1")) << budget.what();
}

// The children this process has now (from /proc: their parent is us).
std::vector<pid_t> children() {
  std::vector<pid_t> found;
  DIR* proc = opendir("/proc");
  while (dirent* entry = proc ? readdir(proc) : nullptr) {
    const pid_t pid = static_cast<pid_t>(std::atoi(entry->d_name));
    if (pid <= 0) continue;
    std::ifstream stat("/proc/" + std::string(entry->d_name) + "/stat");
    std::string line;
    std::getline(stat, line);
    const auto close = line.rfind(')');
    if (close == std::string::npos) continue;
    char state = 0;
    int parent = 0;
    if (std::sscanf(line.c_str() + close + 1, " %c %d", &state, &parent) == 2 && parent == getpid())
      found.push_back(pid);
  }
  if (proc) closedir(proc);
  return found;
}

TEST(VdbIsolated, AChildThatDiesIsAnErrorNamingTheFile) {
  const std::string path = write_grid("isolated-killed.vdb");
  ASSERT_TRUE(children().empty());
  const auto reader = open_vdb_slabs(path);
  const std::vector<pid_t> child = children();
  ASSERT_EQ(child.size(), 1u);
  ASSERT_EQ(::kill(child[0], SIGKILL), 0);
  std::vector<float> values(std::size_t{5} * 4 * 7);
  const Error killed = error_of([&] { reader->read(0, 7, values.data()); });
  EXPECT_EQ(killed.error_class(), ErrorClass::Malformed);
  EXPECT_TRUE(contains(killed.what(), path + ": libopenvdb crashed (signal 9")) << killed.what();
  EXPECT_TRUE(contains(killed.what(), "reading slices 0 .. 7 of grid 'temperature'")) << killed.what();
}

// A 10 KB file whose blosc block header claims 64 GiB (found by fuzz_vdb):
// libopenvdb allocates it before reading. This process runs under an
// address-space limit of what it has plus 512 MiB, which only the child
// raises for itself: the error must come from the child (its limit named),
// and this process must not have grown.
TEST(VdbIsolated, AHugeAllocationIsRefusedInTheChildNotHere) {
  const std::string path = std::string(IVOL_SOURCE_DIR) + "/tests/fuzz/regressions/vdb/vdb-blosc-64gib-allocation";
#if defined(__SANITIZE_ADDRESS__)
  // No address-space limit under AddressSanitizer (its shadow would count),
  // and its operator new aborts on the request instead of throwing: the
  // child dies, which must still be an error naming the file, not the end of
  // this process.
  const Error died = error_of([&] { open_vdb_slabs(path); });
  EXPECT_TRUE(contains(died.what(), path)) << died.what();
  return;
#endif
  std::ifstream statm("/proc/self/statm");
  std::uint64_t pages = 0;
  statm >> pages;
  rlimit before{};
  ASSERT_EQ(getrlimit(RLIMIT_AS, &before), 0);
  rlimit capped = before;
  const std::uint64_t cap = pages * sysconf(_SC_PAGESIZE) + (std::uint64_t{512} << 20);
  if (before.rlim_cur == RLIM_INFINITY || before.rlim_cur > cap) capped.rlim_cur = cap;
  ASSERT_EQ(setrlimit(RLIMIT_AS, &capped), 0);
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const long resident_before_kb = usage.ru_maxrss;
  const Error error = error_of([&] { open_vdb_slabs(path); });
  setrlimit(RLIMIT_AS, &before);
  EXPECT_EQ(error.error_class(), ErrorClass::LimitExceeded) << error.what();
  EXPECT_TRUE(contains(error.what(), path + ": grid 'tiles': libopenvdb could not allocate")) << error.what();
  EXPECT_TRUE(contains(error.what(), "the process that runs the library may allocate 4096 MiB")) << error.what();
  getrusage(RUSAGE_SELF, &usage);
  EXPECT_LT(usage.ru_maxrss - resident_before_kb, 64 * 1024) << "this process grew by " << usage.ru_maxrss << " KB";
}

}  // namespace
}  // namespace ivol::convert
