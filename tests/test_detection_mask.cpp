// The detection rule's need mask computed layer by layer (issue 23) is the
// mask of the whole preview (reconstruct_detection_preview, then
// need_mask_from_low_resolution: every sample held, Otsu's threshold by
// otsu_threshold over them, a byte per cell), cell for cell and with the
// same Otsu's threshold, whether the cell layers and Otsu's samples stay in
// memory, all go to temporary files or part each, and however thin the
// FDK's slabs; its mask (1 bit per cell) generates the same structures as
// the byte mask; a budget below what it must hold is refused. The spool the
// layers wait in gives back every record as put, compressed or not.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "host_spool.hpp"
#include "ivol/error.hpp"
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
  ASSERT_TRUE(layered.mask.packed());
  ASSERT_FALSE(reference.packed());
  EXPECT_EQ(layered.mask.bits.size(), (reference.need.size() + 63) / 64);
  std::size_t needed = 0, differing = 0;
  for (std::size_t i = 0; i < reference.need.size(); ++i) {
    needed += reference.need[i];
    differing += layered.mask.at(i) != (reference.need[i] != 0);
  }
  // The packing's tail bits stay clear.
  for (std::size_t i = reference.need.size(); i < layered.mask.bits.size() * 64; ++i)
    EXPECT_FALSE(layered.mask.at(i)) << i;
  EXPECT_EQ(differing, 0U);
  // Neither all nor nothing: the mask finds an object.
  EXPECT_GT(needed, reference.need.size() / 20);
  EXPECT_LT(needed, reference.need.size());
  const std::uint64_t whole_bytes = whole.values.size() * sizeof(float);
  if (expect_spill) {
    EXPECT_GT(layered.spilled_bytes, 0U);
    EXPECT_LE(layered.spilled_bytes, 2 * whole_bytes);  // cells, and Otsu's samples (fewer); exact counts below
  } else {
    EXPECT_EQ(layered.spilled_bytes, 0U);
  }
  EXPECT_GT(layered.peak_preview_bytes, 0U);
}

TEST(DetectionMask, InMemoryIsTheWholePreviewsMask) {
  PhantomScan scan;
  expect_same_as_whole_preview(scan, 2, std::uint64_t{1} << 30, 0, std::nullopt, false);
}

DetectionMaskOptions rule_options(unsigned factor) {
  DetectionMaskOptions options;
  options.rule = DetectionRule{factor, 2, 2, 0.3};
  options.margin_voxels = 3;
  return options;
}

TEST(DetectionMask, AllSpilledWithThinSlabsIsTheWholePreviewsMask) {
  PhantomScan scan;
  // The smallest budget: every cell layer and every sample for Otsu's
  // threshold goes to the temporary files, and Otsu's threshold is still the
  // one over all samples held at once.
  for (unsigned factor : {4U, 2U}) {
    const std::uint64_t least = detection_fixed_bytes(scan.grid, rule_options(factor));
    expect_same_as_whole_preview(scan, factor, least, factor == 4 ? 1 : 3, std::nullopt, true);
    DetectionMaskOptions options = rule_options(factor);
    options.preview_memory = least;
    const DetectionMask spilled = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, options);
    EXPECT_EQ(spilled.peak_preview_bytes, least);
    // Cells (binary16 each) and one sample in eight of every even slice of
    // samples (float32), before compression; compressed, no more than that.
    const VolumeGrid& cells = spilled.grid;
    const unsigned spacing = factor > 2 ? factor / 2 : factor;
    const std::uint64_t sx = (46 + spacing - 1) / spacing, sy = (38 + spacing - 1) / spacing,
                        sz = (43 + spacing - 1) / spacing;
    EXPECT_EQ(spilled.spilled_raw_bytes,
              2 * cells.voxel_count() + 4 * ((sx + 1) / 2) * ((sy + 1) / 2) * ((sz + 1) / 2));
    EXPECT_GT(spilled.spilled_bytes, 0U);
    EXPECT_LE(spilled.spilled_bytes, spilled.spilled_raw_bytes);
  }
}

TEST(DetectionMask, BudgetBelowWhatItHoldsIsRefused) {
  PhantomScan scan;
  DetectionMaskOptions options = rule_options(2);
  const std::uint64_t least = detection_fixed_bytes(scan.grid, options);
  // The ring of 1 + 1 + 2·2 slices of 23×19 cells, the slice buffers and 1 bit per cell.
  // A layer of cells as floats and as binary16, a row of Otsu's samples.
  const std::uint64_t ring = 6 * 23 * 19 * 4, along_x = 23 * 19 * 4, cells = 23 * 19 * (4 + 2), otsu_row = 12 * 10 * 4;
  const std::uint64_t mask = (23 * 19 * 22 + 63) / 64 * 8;
  EXPECT_EQ(least, ring + along_x + cells + otsu_row + mask);
  options.preview_memory = least - 1;
  try {
    detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, options);
    FAIL() << "a budget below the fixed bytes was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::LimitExceeded);
    const std::string text = e.what();
    EXPECT_NE(text.find(std::to_string(least - 1) + " bytes is below the " + std::to_string(least)), std::string::npos)
        << text;
    EXPECT_NE(text.find("23x19 cells"), std::string::npos) << text;
  }
}

// The packed mask generates, for every structure kind, the bricks the byte
// mask generates.
TEST(DetectionMask, PackedMaskGeneratesTheSameStructures) {
  PhantomScan scan;
  DetectionMaskOptions options = rule_options(2);
  const DetectionMask packed = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, options);
  NeedMask bytes = packed.mask;
  bytes.bits.clear();
  for (std::uint64_t n = 0; n < std::uint64_t{23} * 19 * 22; ++n) bytes.need.push_back(packed.mask.at(n) ? 1 : 0);
  ASSERT_FALSE(bytes.packed());
  for (StructureKind kind : {StructureKind::Octree, StructureKind::Nested, StructureKind::Rectilinear}) {
    const auto a = generate_structure(kind, packed.mask);
    const auto b = generate_structure(kind, bytes);
    EXPECT_EQ(a->voxel_count(), b->voxel_count());
    if (kind == StructureKind::Octree) EXPECT_LT(a->voxel_count(), scan.grid.voxel_count());
    ASSERT_EQ(a->bricks().size(), b->bricks().size());
    for (std::size_t n = 0; n < a->bricks().size(); ++n) {
      const Brick& x = a->bricks()[n];
      const Brick& y = b->bricks()[n];
      EXPECT_TRUE(x.origin == y.origin && x.count == y.count && x.voxel == y.voxel) << n;
    }
  }
}

TEST(DetectionMask, PartlySpilledWithAGivenThreshold) {
  PhantomScan scan;
  // All held: the peak is everything else plus every layer of 23×19 cells.
  DetectionMaskOptions all;
  all.margin_voxels = 3;
  const DetectionMask held = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, all);
  const std::uint64_t layer_bytes = 23 * 19 * sizeof(std::uint16_t);
  const std::uint64_t layers = 22;  // ceil(43 / 2)
  EXPECT_EQ(held.spilled_bytes, 0U);
  ASSERT_GT(held.peak_preview_bytes, layers * layer_bytes);
  // Three layers held, the rest spilled.
  // Three layers' worth less than all: the cells and Otsu's samples share
  // the rest, so the three layers' bytes go to the files in layers or samples.
  const std::uint64_t budget = held.peak_preview_bytes - (layers - 3) * layer_bytes;
  expect_same_as_whole_preview(scan, 2, budget, 2, 0.01F, true);
  all.preview_memory = budget;
  const DetectionMask partly = detect_need_mask(scan.projections, scan.geometry, {}, scan.grid, all);
  EXPECT_GE(partly.spilled_raw_bytes, (layers - 3) * layer_bytes);
  EXPECT_LE(partly.spilled_raw_bytes, (layers - 3) * layer_bytes + 2 * layer_bytes);
  EXPECT_LE(partly.spilled_bytes, partly.spilled_raw_bytes);
  EXPECT_LE(partly.peak_preview_bytes, budget);
  EXPECT_EQ(partly.peak_preview_bytes + partly.spilled_raw_bytes, held.peak_preview_bytes);
}

// Records held, then spilled: smooth ones (compressed) and random ones
// (stored as they are), read back out of order, bit for bit.
TEST(RecordSpool, GivesBackEveryRecordCompressedOrNot) {
  TempDir temp;
  constexpr std::size_t kFloats = 4096;
  detail::HostAllowance allowance{3 * kFloats * sizeof(float), 0};
  detail::RecordSpool spool(kFloats * sizeof(float), sizeof(float), allowance, temp.path, "the test's records");
  std::mt19937 rng(11);
  std::vector<std::vector<float>> put(12, std::vector<float>(kFloats));
  for (std::size_t r = 0; r < put.size(); ++r) {
    for (std::size_t i = 0; i < kFloats; ++i) {
      if (r % 2 == 0) {
        put[r][i] = 0.01F * static_cast<float>(i % 64) + static_cast<float>(r);
      } else {
        std::uint32_t bits = rng();
        std::memcpy(&put[r][i], &bits, 4);
      }
    }
    spool.put(r, put[r].data());
  }
  // A held record may be put again; a spilled one, or one out of order, not.
  put[1][7] = 42.0F;
  spool.put(1, put[1].data());
  EXPECT_THROW(spool.put(5, put[5].data()), std::logic_error);
  EXPECT_THROW(spool.put(13, put[5].data()), std::logic_error);
  EXPECT_EQ(spool.held_bytes(), 3 * kFloats * sizeof(float));
  EXPECT_EQ(spool.spilled_raw_bytes(), 9 * kFloats * sizeof(float));
  // The four smooth records spilled (4, 6, 8, 10) compress; the five random
  // ones are stored as they are.
  EXPECT_LT(spool.spilled_bytes(), 5 * kFloats * sizeof(float) + 4 * kFloats * sizeof(float) / 4);
  EXPECT_GE(spool.spilled_bytes(), 5 * kFloats * sizeof(float));
  std::vector<float> got(kFloats);
  for (std::size_t r : {11, 0, 7, 4, 1, 10, 2, 3, 5, 6, 8, 9}) {
    spool.get(r, got.data());
    ASSERT_EQ(std::memcmp(got.data(), put[r].data(), kFloats * sizeof(float)), 0) << r;
  }
  EXPECT_THROW(spool.get(12, got.data()), std::logic_error);
  spool.release();
  EXPECT_EQ(allowance.held, 0U);
}

}  // namespace
}  // namespace ivol::recon
