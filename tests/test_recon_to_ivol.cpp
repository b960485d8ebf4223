// The FDK written straight into .ivol (what `ivol recon` does): the file
// holds the dense reconstruction within binary16 rounding, or exactly with
// float32; with a keep rule the full-resolution region still does.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "ivol/binary16.hpp"
#include "ivol/reader.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol_io.hpp"
#include "recon_slabs.hpp"

namespace ivol {
namespace {

struct Scan {
  recon::ScanGeometry geometry = recon::circular_scan({96, 80, 1.2, 1.2}, 90, 300.0, 600.0, 2 * M_PI, 0.1, 1.5, -2.0);
  recon::VolumeGrid grid = recon::VolumeGrid::centred({40, 36, 33}, 1.0);
  recon::InMemoryProjections projections = recon::project_scan(recon::pencil_holder(18.0), geometry);
};

std::string temp_path(const char* name) {
  return (std::filesystem::temp_directory_path() / (std::string("ivol_recon_") + name)).string();
}

std::vector<float> read_all(const std::string& path, const recon::VolumeGrid& grid) {
  Reader reader(path);
  return reader.read_box(Box{{0, 0, 0}, {grid.size[0], grid.size[1], grid.size[2]}});
}

TEST(ReconToIvol, DenseFileHoldsTheReconstruction) {
  Scan scan;
  const std::vector<float> dense = recon::reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid);
  recon::FdkReconstructor reconstructor(scan.projections, scan.geometry);
  for (const ValueEncoding encoding : {ValueEncoding::Binary16, ValueEncoding::Float32}) {
    const std::string path = temp_path("dense.ivol");
    convert::ReconstructionSlabs slabs(reconstructor, scan.grid, 0);
    convert::ImportOptions options;
    options.encoding = encoding;
    options.slab_budget_bytes = 8 * 40 * 36 * 4;  // slabs of 8 slices: several reconstructions
    convert::import_to_ivol(slabs, path, options);
    EXPECT_EQ(slabs.slices_reconstructed(), scan.grid.size[2]);
    const std::vector<float> stored = read_all(path, scan.grid);
    ASSERT_EQ(stored.size(), dense.size());
    for (std::size_t i = 0; i < dense.size(); ++i) {
      const float expected =
          encoding == ValueEncoding::Float32 ? dense[i] : binary16_to_float(float_to_binary16(dense[i]));
      ASSERT_EQ(stored[i], expected) << "voxel " << i;
    }
    std::filesystem::remove(path);
  }
}

TEST(ReconToIvol, KeptRegionEqualsDenseWithinBinary16) {
  Scan scan;
  const std::vector<float> dense = recon::reconstruct_fdk_dense(scan.projections, scan.geometry, scan.grid);
  recon::FdkReconstructor reconstructor(scan.projections, scan.geometry);
  const recon::Preview preview = recon::reconstruct_preview(scan.projections, scan.geometry, {}, scan.grid, 4);
  // The cup's plastic (0.02/mm) against air: Otsu lands between them.
  EXPECT_GT(preview.otsu_threshold, 0.002F);
  EXPECT_LT(preview.otsu_threshold, 0.02F);
  const std::string path = temp_path("kept.ivol");
  convert::ReconstructionSlabs slabs(reconstructor, scan.grid, 2);
  convert::ImportOptions options;
  options.encoding = ValueEncoding::Binary16;
  options.keep = convert::KeepRule{false, preview.otsu_threshold, 2};
  options.slab_budget_bytes = 8 * 40 * 36 * 4;
  const convert::ImportReport report = convert::import_to_ivol(slabs, path, options);
  // Each slab is read with 2 slices on either side; the 4 read again by the
  // next slab come from the previous read, so no slice is made twice.
  EXPECT_EQ(slabs.slices_reconstructed(), scan.grid.size[2]);
  EXPECT_LT(report.kept_voxels, scan.grid.voxel_count() / 2);
  EXPECT_GT(report.kept_voxels, 0U);
  const std::vector<float> stored = read_all(path, scan.grid);
  std::size_t checked = 0;
  for (std::size_t i = 0; i < dense.size(); ++i) {
    if (!(dense[i] > preview.otsu_threshold)) continue;  // object voxels are always kept
    ASSERT_EQ(stored[i], binary16_to_float(float_to_binary16(dense[i]))) << "voxel " << i;
    ++checked;
  }
  EXPECT_GT(checked, 1000U);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace ivol
