// The refinement rule keeps the object (issue 18): on a scan of wires and
// sheets one voxel thin with gaps of one voxel, every voxel of the object
// (the dense reconstruction above its Otsu's threshold) lands in a
// full-resolution voxel of the octree and holds the dense reconstruction's
// bits. The dense volume is reconstructed separately, as the reference; the
// rule before issue 18 (a 1/4 preview's centre values, half of Otsu's
// threshold, a margin of whole cells) loses some of the same wires, which
// shows that the check can fail.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>

#include "ivol/keep_mask.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structures.hpp"

namespace ivol::recon {
namespace {

constexpr std::uint32_t kSize = 64;

struct WireScan {
  // The recon_bench geometry at 64³: 1 mm voxels, a detector 1.2 times the
  // field, source and detector at 600 and 1200 mm.
  ScanGeometry geometry =
      circular_scan({96, 96, 2.0 * kSize * 1.2 / 96, 2.0 * kSize * 1.2 / 96}, 180, 600.0, 1200.0, 2 * M_PI);
  VolumeGrid grid = VolumeGrid::centred({kSize, kSize, kSize}, 1.0);
  // Wires and gaps one voxel (1 mm) wide.
  InMemoryProjections projections = project_scan(fine_wires(0.5 * kSize, 1.0), geometry);
  std::vector<float> dense = reconstruct_fdk_dense(projections, geometry, grid);
  float object_threshold = otsu_threshold(dense.data(), dense.size());
};

struct Kept {
  std::uint64_t object = 0;  // voxels of the object
  std::uint64_t exact = 0;   // of them, those whose structure value has the dense bits
  std::uint64_t structure_voxels = 0;
  double share() const { return static_cast<double>(exact) / static_cast<double>(object); }
};

// Reconstructs straight into the octree the mask gives and compares it with
// the dense reconstruction, bit for bit, over the object.
Kept reconstruct_and_compare(WireScan& scan, const NeedMask& mask) {
  auto octree = generate_structure(StructureKind::Octree, mask);
  FdkReconstructor reconstructor(scan.projections, scan.geometry);
  reconstructor.reconstruct_structure(scan.grid, *octree);
  std::vector<float> back(scan.grid.voxel_count());
  octree->to_dense(back.data());
  Kept kept;
  kept.structure_voxels = octree->voxel_count();
  for (std::size_t i = 0; i < back.size(); ++i) {
    if (!(scan.dense[i] > scan.object_threshold)) continue;
    ++kept.object;
    kept.exact += std::memcmp(&back[i], &scan.dense[i], sizeof(float)) == 0;
  }
  return kept;
}

Dims dims_of(const VolumeGrid& grid) { return Dims{grid.size[0], grid.size[1], grid.size[2]}; }

TEST(RefinementRule, DetectionKeepsEveryOneVoxelWireAtFullResolution) {
  WireScan scan;
  const DetectionRule rule;
  const Preview detection = reconstruct_detection_preview(scan.projections, scan.geometry, {}, scan.grid, rule.factor,
                                                          rule.thinning, rule.margin);
  const NeedMask mask =
      need_mask_from_low_resolution(detection.values.data(), dims_of(detection.grid), rule.factor, dims_of(scan.grid),
                                    static_cast<float>(rule.otsu_share * detection.otsu_threshold), 0);
  const Kept kept = reconstruct_and_compare(scan, mask);
  std::printf("detection rule: %llu of %llu object voxels exact (%.4f %%), %llu structure voxels\n",
              static_cast<unsigned long long>(kept.exact), static_cast<unsigned long long>(kept.object),
              100.0 * kept.share(), static_cast<unsigned long long>(kept.structure_voxels));
  ASSERT_GT(kept.object, 1000U);  // the wires are there, above the threshold
  EXPECT_GE(kept.share(), 0.9999);
  // Still an inhomogeneous structure: most of the volume is coarse.
  EXPECT_LT(kept.structure_voxels, scan.grid.voxel_count() / 2);

  // The rule before issue 18 on the same scan loses wires.
  const Preview preview = reconstruct_preview(scan.projections, scan.geometry, {}, scan.grid, 4);
  const NeedMask old_mask = need_mask_from_low_resolution(preview.values.data(), dims_of(preview.grid), 4,
                                                          dims_of(scan.grid), 0.5F * preview.otsu_threshold, 2);
  const Kept old = reconstruct_and_compare(scan, old_mask);
  std::printf("preview rule: %llu of %llu object voxels exact (%.4f %%), %llu structure voxels\n",
              static_cast<unsigned long long>(old.exact), static_cast<unsigned long long>(old.object),
              100.0 * old.share(), static_cast<unsigned long long>(old.structure_voxels));
  EXPECT_LT(old.share(), 0.9999);
}

}  // namespace
}  // namespace ivol::recon
