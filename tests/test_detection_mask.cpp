// The detection rule's need mask computed layer by layer (issue 23) is the
// mask of the whole preview (reconstruct_detection_preview, then
// need_mask_from_low_resolution), cell for cell and with the same Otsu's
// threshold, whether the cell layers stay in memory, all go to the temporary
// file or part each, and however thin the FDK's slabs.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <cmath>
#include <string>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structures.hpp"

namespace ivol::recon {
namespace {

// An uneven grid (not a cube, not a multiple of the factors) so that a
// layer or axis mixed up shows.
struct PhantomScan {
  ScanGeometry geometry = circular_scan({80, 72, 1.0, 1.0}, 120, 500.0, 1000.0, 2 * M_PI);
  VolumeGrid grid = VolumeGrid::centred({46, 38, 43}, 0.6);
  InMemoryProjections projections = project_scan(shepp_logan_3d(12.0), geometry);
};

Dims dims_of(const VolumeGrid& grid) { return Dims{grid.size[0], grid.size[1], grid.size[2]}; }

struct TempDir {
  std::string path;
  TempDir() {
    std::string name = ::testing::TempDir() + "ivol-detection-mask-XXXXXX";
    path = ::mkdtemp(name.data());
  }
  ~TempDir() { ::rmdir(path.c_str()); }
};

void expect_same_as_whole_preview(PhantomScan& scan, unsigned factor, std::uint64_t preview_memory,
                                  std::uint32_t max_slab_slices, std::optional<float> given, bool expect_spill) {
  const DetectionRule rule{factor, 2, 2, 0.3};
  FdkOptions fdk;
  fdk.max_slab_slices = max_slab_slices;
  const Preview whole =
      reconstruct_detection_preview(scan.projections, scan.geometry, fdk, scan.grid, factor, rule.thinning, 3);
  const float threshold = given ? *given : static_cast<float>(rule.otsu_share * whole.otsu_threshold);
  const NeedMask reference =
      need_mask_from_low_resolution(whole.values.data(), dims_of(whole.grid), factor, dims_of(scan.grid), threshold, 0);
  TempDir temp;
  DetectionMaskOptions options;
  options.rule = rule;
  options.margin_voxels = 3;
  options.threshold = given;
  options.preview_memory = preview_memory;
  options.temp_directory = temp.path;
  const DetectionMask layered = detect_need_mask(scan.projections, scan.geometry, fdk, scan.grid, options);

  EXPECT_EQ(layered.otsu_threshold, whole.otsu_threshold);
  EXPECT_EQ(layered.threshold, threshold);
  EXPECT_EQ(layered.mask.dims, reference.dims);
  EXPECT_EQ(layered.mask.cells, reference.cells);
  EXPECT_EQ(layered.mask.factor, reference.factor);
  ASSERT_EQ(layered.mask.need.size(), reference.need.size());
  std::size_t needed = 0, differing = 0;
  for (std::size_t i = 0; i < reference.need.size(); ++i) {
    needed += reference.need[i];
    differing += layered.mask.need[i] != reference.need[i];
  }
  EXPECT_EQ(differing, 0U);
  // Neither all nor nothing: the mask finds an object.
  EXPECT_GT(needed, reference.need.size() / 20);
  EXPECT_LT(needed, reference.need.size());
  const std::uint64_t whole_bytes = whole.values.size() * sizeof(float);
  if (expect_spill) {
    EXPECT_GT(layered.spilled_bytes, 0U);
    EXPECT_LE(layered.spilled_bytes, whole_bytes);
  } else {
    EXPECT_EQ(layered.spilled_bytes, 0U);
  }
  EXPECT_GT(layered.peak_preview_bytes, 0U);
}

TEST(DetectionMask, InMemoryIsTheWholePreviewsMask) {
  PhantomScan scan;
  expect_same_as_whole_preview(scan, 2, std::uint64_t{1} << 30, 0, std::nullopt, false);
}

TEST(DetectionMask, AllSpilledWithThinSlabsIsTheWholePreviewsMask) {
  PhantomScan scan;
  expect_same_as_whole_preview(scan, 4, 0, 1, std::nullopt, true);
  expect_same_as_whole_preview(scan, 2, 0, 3, std::nullopt, true);
}

TEST(DetectionMask, PartlySpilledWithAGivenThreshold) {
  PhantomScan scan;
  // All held: the peak is everything else plus every layer of 23×19 cells.
  DetectionMaskOptions all;
  all.margin_voxels = 3;
  const DetectionMask held = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, all);
  const std::uint64_t layer_bytes = 23 * 19 * sizeof(float);
  const std::uint64_t layers = 22;  // ceil(43 / 2)
  EXPECT_EQ(held.spilled_bytes, 0U);
  ASSERT_GT(held.peak_preview_bytes, layers * layer_bytes);
  // Three layers held, the rest spilled.
  const std::uint64_t budget = held.peak_preview_bytes - (layers - 3) * layer_bytes;
  expect_same_as_whole_preview(scan, 2, budget, 2, 0.01F, true);
  all.preview_memory = budget;
  const DetectionMask partly = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, all);
  EXPECT_EQ(partly.spilled_bytes, (layers - 3) * layer_bytes);
  EXPECT_EQ(partly.peak_preview_bytes, budget);
}

}  // namespace
}  // namespace ivol::recon
