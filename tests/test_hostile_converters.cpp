// Converter inputs made to break size arithmetic and memory bounds (issue 17):
// sizes whose products wrap past 2^64, a one-leaf file of 2^31 per side,
// OpenVDB grids at the edges of the 32-bit index space, a TIFF page that
// inflates to gigabytes, an HDF5 dataset in one huge compressed chunk and a
// TIFF of 100 000 pages. Each must end in ivol::Error of the right class (or
// in the right values, in bounded time), never in a crash, a hang or a file
// that claims what it does not hold.
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>

#include "hdf5_io.hpp"
#include "ivol/error.hpp"
#include "ivol/octree.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "ivol_io.hpp"
#include "projection_io.hpp"
#include "raw_io.hpp"
#include "sizes.hpp"
#include "slab_io.hpp"
#include "test_support.hpp"
#include "tiff_io.hpp"
#include "vdb_io.hpp"

namespace ivol::convert {
namespace {

using ivol::test::run_command;
using ivol::test::temp_path;

// Runs `f` and returns the class of the ivol::Error it throws; fails the
// test when it throws nothing.
template <typename F>
ErrorClass error_class_of(F&& f, std::string* message = nullptr) {
  try {
    f();
  } catch (const Error& e) {
    if (message) *message = e.what();
    return e.error_class();
  }
  ADD_FAILURE() << "no ivol::Error was thrown";
  return ErrorClass::InvalidArgument;
}

void touch(const std::string& path) { std::ofstream(path, std::ios::binary | std::ios::trunc); }

std::size_t entries_in(const std::string& folder) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(folder)) ++n;
  return n;
}

TEST(HostileConverters, CheckedMultiplicationRefusesWhatWraps) {
  EXPECT_EQ(checked_mul(std::uint64_t{1} << 31, std::uint64_t{1} << 31, "x"), std::uint64_t{1} << 62);
  std::string message;
  EXPECT_EQ(error_class_of([] { checked_mul(std::uint64_t{1} << 62, 4, "the samples"); }, &message),
            ErrorClass::LimitExceeded);
  EXPECT_NE(message.find("the samples"), std::string::npos) << message;
  EXPECT_NE(message.find("4611686018427387904 x 4"), std::string::npos) << message;
}

// 2^31 x 2^31 x 4 samples of one byte are 2^64 bytes, which wrapped to 0 and
// matched an empty file; the import then wrote a 731-byte "lossless" file
// that claimed them.
TEST(HostileConverters, RawSizeThatWrapsPast64BitsIsRefused) {
  const std::string path = temp_path("empty.raw");
  touch(path);
  for (const SampleType type : {SampleType::UInt8, SampleType::Float32}) {
    RawLayout layout;
    layout.type = type;
    layout.dims = {1u << 31, 1u << 31, type == SampleType::UInt8 ? 4u : 1u};
    std::string message;
    EXPECT_EQ(error_class_of([&] { open_raw_slabs(path, layout); }, &message), ErrorClass::LimitExceeded);
    EXPECT_NE(message.find("empty.raw"), std::string::npos) << message;
    EXPECT_NE(message.find("2^64"), std::string::npos) << message;
  }
}

// A valid file whose root is one leaf: 2^31 voxels per side, a few hundred
// bytes. Exporting it divided by a slice size that had wrapped to 0 (SIGFPE).
std::string one_leaf_file(const std::string& name) {
  VolumeLayout layout;
  layout.dims = {1u << 31, 1u << 31, 1u << 31};
  layout.depth = 31;
  layout.encoding = ValueEncoding::Binary16;
  layout.inner_count.assign(layout.depth + 1, 0);
  const std::vector<std::uint8_t> value{0x00, 0x3c};  // 1.0 in binary16, little-endian
  const Octree octree(layout, {}, value);
  const std::string path = temp_path(name);
  write_octree(octree, Metadata{}, path);
  return path;
}

TEST(HostileConverters, ExportOfOneLeafFileOfTwoToThe31PerSideIsRefused) {
  const std::string path = one_leaf_file("one-leaf.ivol");
  Reader reader(path);
  ASSERT_EQ(reader.layout().dims, (Dims{1u << 31, 1u << 31, 1u << 31}));
  const std::string folder = temp_path("one-leaf-out");
  std::filesystem::create_directories(folder);
  for (const SampleType type : {SampleType::UInt8, SampleType::Float32}) {
    const Box box = full_box(reader.layout().dims, 0);
    const DenseVolume shape = export_shape(reader, box, 0, type);
    std::string message;
    EXPECT_EQ(error_class_of(
                  [&] {
                    auto sink = create_raw_slabs(folder + "/x.raw", shape, false);
                    export_from_ivol(reader, box, 0, type, *sink);
                  },
                  &message),
              ErrorClass::LimitExceeded);
    EXPECT_NE(message.find("2147483648x2147483648"), std::string::npos) << message;
    EXPECT_EQ(entries_in(folder), 0u) << "a refused export left its temporary file";
  }
  // At a coarse level the same file exports: one slice of 2^31 / 2^24 = 128^2.
  const Box coarse = full_box(reader.layout().dims, 24);
  const DenseVolume volume = export_from_ivol(reader, coarse, 24, SampleType::Float32);
  ASSERT_EQ(volume.dims, (Dims{128, 128, 128}));
  EXPECT_EQ(volume.value(0), 1.0);
  EXPECT_EQ(volume.value(volume.voxel_count() - 1), 1.0);
}

void save(const std::string& path, const openvdb::FloatGrid::Ptr& grid) {
  openvdb::io::File file(path);
  file.write({grid});
  file.close();
}

// Active voxels at both ends of x: the bounding box spans 2^32 voxels and
// Coord::dim() wrapped to 0 (copyToDense then wrote out of bounds).
TEST(HostileConverters, VdbBoxSpanningTheWholeIndexSpaceIsRefused) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  grid->tree().setValue(openvdb::Coord(std::numeric_limits<int>::min(), 0, 0), 1.0f);
  grid->tree().setValue(openvdb::Coord(std::numeric_limits<int>::max(), 0, 0), 2.0f);
  const std::string path = temp_path("span.vdb");
  save(path, grid);
  std::string message;
  EXPECT_EQ(error_class_of([&] { read_vdb(path); }, &message), ErrorClass::LimitExceeded);
  EXPECT_NE(message.find("4294967296 voxels along x"), std::string::npos) << message;
}

// Just past 2^31 along x: the extent fits in 32 bits unsigned, but 2^31
// voxels held densely are 12 GiB, beyond the default budget.
TEST(HostileConverters, VdbBoxBeyondTheMemoryBudgetIsRefusedBeforeAllocating) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  grid->tree().setValue(openvdb::Coord(-(1 << 30) - 5, 0, 0), 1.0f);
  grid->tree().setValue(openvdb::Coord((1 << 30) + 5, 0, 0), 2.0f);
  const std::string path = temp_path("wide.vdb");
  save(path, grid);
  std::string message;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(error_class_of([&] { read_vdb(path); }, &message), ErrorClass::LimitExceeded);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 10.0);
  EXPECT_NE(message.find("2147483659x1x1"), std::string::npos) << message;
  EXPECT_NE(message.find("--memory"), std::string::npos) << message;
}

// Voxels and an active tile next to INT_MIN on every axis: copyToDense
// looped for minutes. The values must be those OpenVDB's accessor gives.
TEST(HostileConverters, VdbVoxelsNearIntMinReadAsTheGridHoldsThem) {
  openvdb::initialize();
  const int m = std::numeric_limits<int>::min();
  auto grid = openvdb::FloatGrid::create(-1.0f);
  grid->setName("density");
  grid->tree().setValue(openvdb::Coord(m, m, m), 1.5f);
  grid->tree().setValue(openvdb::Coord(m + 9, m + 2, m + 17), 2.5f);
  grid->tree().addTile(1, openvdb::Coord(m + 8, m + 8, m + 8), 3.5f, true);
  const std::string path = temp_path("intmin.vdb");
  save(path, grid);
  const VdbVolume read = read_vdb(path);
  ASSERT_EQ(read.volume.dims, (Dims{16, 16, 18}));  // the tile covers x and y 8..15
  const openvdb::FloatGrid::ConstAccessor accessor = grid->getConstAccessor();
  std::uint64_t i = 0, active = 0;
  for (std::uint32_t z = 0; z < 18; ++z)
    for (std::uint32_t y = 0; y < 16; ++y)
      for (std::uint32_t x = 0; x < 16; ++x, ++i) {
        const openvdb::Coord c(m + int(x), m + int(y), m + int(z));
        ASSERT_EQ(read.volume.value(i), accessor.getValue(c)) << x << "," << y << "," << z;
        ASSERT_EQ(read.active[i] != 0, accessor.isValueOn(c)) << x << "," << y << "," << z;
        active += read.active[i];
      }
  EXPECT_EQ(active, grid->activeVoxelCount());
}

// A 16384^2 page of zeros deflates to a few hundred KB and held as one slab
// with its codes and the writer's share it took 5.2 GiB with --memory 256;
// the budget is now weighed before the first page is read. A smaller page
// keeps the test light: 4096^2 u8 under a 16 MiB budget.
TEST(HostileConverters, SliceLargerThanTheMemoryBudgetIsRefused) {
  const std::string tif = temp_path("page.tif");
  const auto made = run_command(std::string(IVOL_PYTHON) + " -c \"import numpy as np, tifffile; tifffile.imwrite('" +
                                tif + "', np.zeros((4096, 4096), np.uint8), compression='zlib', rowsperstrip=4096)\"");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  const auto source = open_tiff_slabs(tif);
  ImportOptions options;
  options.memory_bytes = 16u << 20;
  options.slab_budget_bytes = options.memory_bytes / 4;
  const std::string out = temp_path("page.ivol");
  std::string message;
  EXPECT_EQ(error_class_of([&] { import_to_ivol(*source, out, options); }, &message), ErrorClass::LimitExceeded);
  EXPECT_NE(message.find("4096x4096 u8"), std::string::npos) << message;
  EXPECT_NE(message.find("16 MiB"), std::string::npos) << message;
  EXPECT_FALSE(std::filesystem::exists(out));
  // With room it converts, and losslessly.
  options.memory_bytes = 512u << 20;
  const ImportReport report = import_to_ivol(*source, out, options);
  EXPECT_TRUE(report.lossless);
  EXPECT_EQ(Reader(out).voxel_value(4095, 4095, 0), 0.0f);
}

// A page larger than the budget is read a band of rows at a time (a
// 16384^2 deflate bomb under --memory 256 into raw): by scanline from
// strips (one strip of the whole page here, so that a band is part of a
// strip) and by tile, each band equal to numpy's samples of those rows.
TEST(HostileConverters, TiffPagesReadByBandsOfRowsEqualNumpysSamples) {
  const std::string dir = temp_path("bands");
  std::filesystem::create_directories(dir);
  const auto made = run_command(
      std::string(IVOL_PYTHON) + " -c \"import numpy as np, tifffile; d = '" + dir +
      "'; v = (np.arange(3 * 700 * 1000, dtype=np.uint64) * 2654435761 % 65521).astype(np.uint16).reshape(3, 700, "
      "1000); v.tofile(d + '/v.raw'); tifffile.imwrite(d + '/strip.tif', v, compression='zlib', rowsperstrip=700, "
      "photometric='minisblack'); tifffile.imwrite(d + '/tiled.tif', v, compression='zlib', tile=(48, 64), "
      "photometric='minisblack')\"");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  std::ifstream in(dir + "/v.raw", std::ios::binary);
  const std::vector<char> expected((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(expected.size(), 3u * 700 * 1000 * 2);
  for (const char* name : {"strip.tif", "tiled.tif"}) {
    const auto reader = open_tiff_slabs(dir + "/" + name, {}, std::uint64_t{4} << 20);
    ASSERT_TRUE(reader->reads_rows());
    ASSERT_EQ(reader->shape().dims, (Dims{1000, 700, 3}));
    // Bands of 37 rows (not a multiple of a tile's 48), pages in order, and
    // one band read again after a later one (libtiff decodes back from the
    // strip's start).
    std::vector<char> band(37 * 1000 * 2);
    for (std::uint32_t z = 0; z < 3; ++z)
      for (std::uint32_t y = 0; y < 700; y += 37) {
        const std::uint32_t n = std::min(37u, 700 - y);
        reader->read_rows(z, y, n, band.data());
        const std::size_t at = (std::size_t{z} * 700 + y) * 2000;
        ASSERT_TRUE(std::equal(band.begin(), band.begin() + n * 2000, expected.begin() + at))
            << name << " page " << z << " rows " << y << " .. " << y + n;
      }
    reader->read_rows(1, 100, 5, band.data());
    EXPECT_TRUE(std::equal(band.begin(), band.begin() + 5 * 2000, expected.begin() + (700 + 100) * 2000)) << name;
    // A tile of 48x64 u16 is 6 KiB: a budget below it is a limit, named.
    if (std::string(name) == "tiled.tif") {
      const auto tight = open_tiff_slabs(dir + "/" + name, {}, 4096);
      std::string message;
      EXPECT_EQ(error_class_of([&] { tight->read_rows(0, 0, 1, band.data()); }, &message), ErrorClass::LimitExceeded);
      EXPECT_NE(message.find("a tile of 64x48"), std::string::npos) << message;
    }
  }
}

// One 2 GiB gzip chunk (9 MB of file) holding a 4x4x4 dataset: libhdf5
// inflates the whole chunk to read 64 bytes. The child that runs it may
// allocate 1 GiB by default, so the read fails there, as a limit.
TEST(HostileConverters, Hdf5ChunkBeyondTheChildsLimitIsALimitNotACrash) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "the child's address-space limit is not set under AddressSanitizer (its shadow would count)";
#endif
  const std::string h5 = temp_path("huge-chunk.h5");
  const auto made = run_command(std::string(IVOL_PYTHON) + " " + IVOL_SOURCE_DIR +
                                "/tests/cli/bad_input.d/make_huge_chunk_h5.py " + h5);
  ASSERT_EQ(made.exit_code, 0) << made.output;
  ASSERT_LT(std::filesystem::file_size(h5), 16u << 20);
  std::string message;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(error_class_of(
                [&] {
                  auto reader = open_hdf5_slabs(h5, "/data");
                  std::vector<std::uint8_t> out(reader->shape().voxel_count());
                  reader->read(0, reader->shape().dims[2], out.data());
                },
                &message),
            ErrorClass::LimitExceeded);
  EXPECT_NE(message.find("huge-chunk.h5"), std::string::npos) << message;
  EXPECT_NE(message.find("1024 MiB"), std::string::npos) << message;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 30.0);
  // The child never held the chunk: its peak stays near the limit.
  rusage children{};
  getrusage(RUSAGE_CHILDREN, &children);
  EXPECT_LT(static_cast<std::uint64_t>(children.ru_maxrss) * 1024, std::uint64_t{3} << 29);
}

// recon's HDF5 projections: the child that reads them may allocate what it
// is given (recon's --memory), not a fixed 1 GiB. 4 views of 4x4 in one
// 256 MiB gzip chunk: a limit naming the file under 64 MiB, zeros under
// 1 GiB.
TEST(HostileConverters, ProjectionChunkBeyondTheChildsLimitFollowsTheMemoryGiven) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "the child's address-space limit is not set under AddressSanitizer (its shadow would count)";
#endif
  const std::string h5 = temp_path("scan-chunk.h5");
  const auto made = run_command(std::string(IVOL_PYTHON) + " " + IVOL_SOURCE_DIR +
                                "/tests/cli/bad_input.d/make_huge_chunk_scan_h5.py " + h5 + " 256");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  DxchangeOptions options;
  options.assume_line_integrals = true;
  options.memory_bytes = std::uint64_t{64} << 20;
  std::vector<float> rows(4 * 4, -1.0f);
  std::string message;
  EXPECT_EQ(error_class_of(
                [&] {
                  Hdf5Scan scan = open_hdf5_projections(h5, options);
                  scan.projections->read_rows(0, 0, 4, rows.data());
                },
                &message),
            ErrorClass::LimitExceeded);
  EXPECT_NE(message.find("scan-chunk.h5"), std::string::npos) << message;
  EXPECT_NE(message.find("64 MiB"), std::string::npos) << message;
  options.memory_bytes = std::uint64_t{1} << 30;
  Hdf5Scan scan = open_hdf5_projections(h5, options);
  ASSERT_EQ(scan.projections->view_count(), 4u);
  scan.projections->read_rows(3, 0, 4, rows.data());
  EXPECT_TRUE(std::all_of(rows.begin(), rows.end(), [](float v) { return v == 0.0f; }));
}

// 100 000 pages of 2x2 (tifffile squeezes 1x1 pages into one image):
// TIFFSetDirectory for each walked the chain from the first page, minutes in
// all; sequential reads follow it (seconds).
TEST(HostileConverters, ManyPageTiffReadsInLinearTime) {
  const std::string tif = temp_path("pages.tif");
  const auto made =
      run_command(std::string(IVOL_PYTHON) + " -c \"import numpy as np, tifffile; tifffile.imwrite('" + tif +
                  "', (np.arange(100000) % 251).astype(np.uint8).repeat(4).reshape(100000, 2, 2), "
                  "photometric='minisblack')\"");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  const auto start = std::chrono::steady_clock::now();
  const auto reader = open_tiff_slabs(tif);
  ASSERT_EQ(reader->shape().dims, (Dims{2, 2, 100000}));
  std::vector<std::uint8_t> pages(4 * 100000);
  for (std::uint32_t z = 0; z < 100000; z += 4096)
    reader->read(z, std::min(4096u, 100000 - z), pages.data() + 4 * std::size_t{z});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  for (std::uint32_t i = 0; i < pages.size(); ++i) ASSERT_EQ(pages[i], i / 4 % 251) << "page " << i / 4;
  EXPECT_LT(seconds, 20.0);
  // Going back (a slab's halo) still finds the page.
  std::uint8_t back[4] = {};
  reader->read(7, 1, back);
  EXPECT_EQ(back[3], 7);
}

}  // namespace
}  // namespace ivol::convert
