// Each detector row of each view is filtered once per reconstructor (issue
// 23), whatever the slabs: thin slabs, several reconstruct() calls, the
// structure path and a budget that sends the rows to a temporary file all
// give the bits of one slab filtered the old way (each slab its own rows),
// and the count of rows filtered is that of one slab.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/structures.hpp"

namespace ivol::recon {
namespace {

struct Scan {
  // The detector's rows reach well above and below the grid (a vertical
  // offset too), so a slab's band is a part of them and bands overlap.
  ScanGeometry geometry = circular_scan({64, 56, 1.2, 1.2}, 72, 300.0, 600.0, 2 * M_PI, 0.1, 1.5, -4.0);
  VolumeGrid grid = VolumeGrid::centred({32, 30, 24}, 1.0);
  InMemoryProjections projections = project_scan(pencil_holder(14.0), geometry);
};

// The reference: one slab, its rows filtered for it (the path before the cache).
std::vector<float> one_slab(Scan& scan, FdkReport& report) {
  FdkOptions options;
  options.cache_filtered_rows = false;
  std::vector<float> v = reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, options, &report);
  EXPECT_EQ(report.slab_count, 1U);
  return v;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

std::filesystem::path fresh_directory(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

TEST(FdkFilteredRows, ThinSlabsFilterEachRowOnce) {
  Scan scan;
  FdkReport whole_report;
  const std::vector<float> whole = one_slab(scan, whole_report);
  const std::uint64_t views = scan.geometry.view_count();
  const std::uint64_t once = whole_report.rows_filtered;
  ASSERT_GT(once, 0U);
  EXPECT_EQ(once % views, 0U);
  EXPECT_LE(once, views * static_cast<std::uint64_t>(scan.geometry.detector.rows));
  for (std::uint32_t slices : {1U, 2U, 5U}) {
    SCOPED_TRACE(std::to_string(slices) + " slices a slab");
    FdkOptions cached;
    cached.max_slab_slices = slices;
    FdkReport report;
    EXPECT_TRUE(same_bits(reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, cached, &report), whole));
    EXPECT_GT(report.slab_count, 1U);
    EXPECT_EQ(report.rows_filtered, once);
    EXPECT_GT(report.filtered_rows_host_bytes, 0U);
    EXPECT_EQ(report.filtered_rows_disk_bytes, 0U);
    // Rows behind the slabs are released: thin slabs never hold them all.
    const std::uint64_t all_rows = 2 * ((once / views + 1) / 2) * views * scan.geometry.detector.columns * 4;
    if (slices == 1) EXPECT_LT(report.filtered_rows_host_bytes, all_rows);

    // Without the cache the same slabs filter their overlapping bands again.
    FdkOptions uncached = cached;
    uncached.cache_filtered_rows = false;
    FdkReport again;
    EXPECT_TRUE(same_bits(reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, uncached, &again), whole));
    EXPECT_GT(again.rows_filtered, once);
  }
  // Two devices (the same one twice) share the filtering and the rows.
  FdkOptions two;
  two.devices = {0, 0};
  two.max_slab_slices = 3;
  FdkReport two_report;
  EXPECT_TRUE(same_bits(reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, two, &two_report), whole));
  EXPECT_EQ(two_report.rows_filtered, once);
}

TEST(FdkFilteredRows, RowsBeyondTheBudgetGoToAnUnlinkedFile) {
  Scan scan;
  FdkReport whole_report;
  const std::vector<float> whole = one_slab(scan, whole_report);
  const auto dir = fresh_directory("ivol-filtered-rows-test");
  // A pair of rows of every view: 2 × columns × views floats.
  const std::uint64_t pair_bytes = 2ULL * scan.geometry.detector.columns * scan.geometry.view_count() * sizeof(float);
  for (std::uint64_t limit : {std::uint64_t{1}, 5 * pair_bytes}) {
    SCOPED_TRACE("budget " + std::to_string(limit));
    FdkOptions options;
    options.max_slab_slices = 2;
    options.filtered_rows_memory_limit = limit;
    options.temp_directory = dir.string();
    FdkReport report;
    EXPECT_TRUE(same_bits(reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, options, &report), whole));
    EXPECT_EQ(report.rows_filtered, whole_report.rows_filtered);
    EXPECT_LE(report.filtered_rows_host_bytes, limit);
    if (limit == 1) EXPECT_EQ(report.filtered_rows_host_bytes, 0U);
    EXPECT_GT(report.filtered_rows_disk_bytes, 0U);
    EXPECT_LE(report.filtered_rows_host_bytes + report.filtered_rows_disk_bytes,
              (whole_report.rows_filtered / scan.geometry.view_count() + 1) / 2 * pair_bytes);
    EXPECT_TRUE(std::filesystem::is_empty(dir)) << "the temporary file has a name";
  }
  FdkOptions nowhere;
  nowhere.max_slab_slices = 2;
  nowhere.filtered_rows_memory_limit = 1;
  nowhere.temp_directory = (dir / "missing").string();
  try {
    reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid, nowhere);
    ADD_FAILURE() << "no error without a temporary directory";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "missing").string()), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

TEST(FdkFilteredRows, LaterCallsReuseTheRows) {
  Scan scan;
  FdkReport whole_report;
  const std::vector<float> whole = one_slab(scan, whole_report);
  const std::size_t slice = std::size_t{scan.grid.size[0]} * scan.grid.size[1];
  FdkReconstructor reconstructor(scan.projections, scan.geometry);
  std::vector<float> volume(whole.size());
  auto sink = [&](std::uint32_t k0, std::uint32_t k1, const float* d) {
    std::copy(d, d + slice * (k1 - k0), volume.begin() + static_cast<std::ptrdiff_t>(slice * k0));
  };
  // Writer slabs of the CLI: each a reconstruct() call of its own.
  std::uint64_t filtered = 0;
  for (std::uint32_t k = 0; k < scan.grid.size[2]; k += 4)
    filtered += reconstructor.reconstruct(scan.grid, sink, k, k + 4).rows_filtered;
  EXPECT_TRUE(same_bits(volume, whole));
  EXPECT_EQ(filtered, whole_report.rows_filtered);
  // The last call's rows stay; the rows behind it went, and come back filtered again.
  const std::uint32_t last = scan.grid.size[2] - 4;
  EXPECT_EQ(reconstructor.reconstruct(scan.grid, sink, last, last + 4).rows_filtered, 0U);
  EXPECT_GT(reconstructor.reconstruct(scan.grid, sink).rows_filtered, 0U);
  EXPECT_TRUE(same_bits(volume, whole));
}

TEST(FdkFilteredRows, StructureSlabsFilterEachRowOnce) {
  Scan scan;
  FdkReport whole_report;
  const std::vector<float> whole = one_slab(scan, whole_report);
  NeedMask mask;
  mask.dims = Dims{scan.grid.size[0], scan.grid.size[1], scan.grid.size[2]};
  mask.factor = 1;
  mask.cells = mask.dims;
  mask.need.assign(scan.grid.voxel_count(), 1);
  auto octree = generate_structure(StructureKind::Octree, mask);
  FdkOptions options;
  options.max_slab_slices = 8;  // whole blocks of IVOL_BACKPROJECT_DEPTH slices
  FdkReconstructor reconstructor(scan.projections, scan.geometry, options);
  const FdkReport report = reconstructor.reconstruct_structure(scan.grid, *octree);
  EXPECT_GT(report.slab_count, 1U);
  std::vector<float> back(scan.grid.voxel_count());
  octree->to_dense(back.data());
  EXPECT_TRUE(same_bits(back, whole));
  EXPECT_LE(report.rows_filtered, whole_report.rows_filtered);
  EXPECT_GT(report.rows_filtered, 0U);
  // Without the cache the structure's slabs filter their overlapping bands again.
  FdkOptions uncached = options;
  uncached.cache_filtered_rows = false;
  auto again = generate_structure(StructureKind::Octree, mask);
  FdkReconstructor plain(scan.projections, scan.geometry, uncached);
  EXPECT_GT(plain.reconstruct_structure(scan.grid, *again).rows_filtered, report.rows_filtered);
  again->to_dense(back.data());
  EXPECT_TRUE(same_bits(back, whole));
}

}  // namespace
}  // namespace ivol::recon
