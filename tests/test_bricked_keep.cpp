// A keep rule written as a bricked grid (--keep … --structure bricked): every
// voxel the rule keeps comes back as it was, every other one as one
// background value, the mean of the values below the threshold. The kept set
// is checked against libformat's threshold_keep_mask on the whole volume,
// the background against a mean the test sums itself.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "dense_volume.hpp"
#include "ivol/binary16.hpp"
#include "ivol/check.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/reader.hpp"
#include "ivol_io.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;
using namespace ivol::convert;

// A part (a ball and a thin plate) in noisy air, 40 x 36 x 70 voxels: more
// than one layer of 32-slice bricks, and sides that are not multiples of 32.
std::vector<float> part_in_air(const Dims& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  std::vector<float> v(voxel_count(d));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const double r = std::hypot(x - 20.0, y - 18.0, z - 30.0);
        const bool plate = z >= 55 && z < 57 && x > 5 && x < 35;
        v[i] = (r < 9 || plate ? 0.05f : 0.0f) + noise(rng);
      }
  return v;
}

DenseVolume as_samples(const std::vector<float>& values, const Dims& d, SampleType type) {
  DenseVolume out = make_dense(d, type);
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (type == SampleType::Float32) {
      std::memcpy(&out.data[4 * i], &values[i], 4);
    } else if (type == SampleType::Float16) {
      const std::uint16_t h = float_to_binary16(values[i]);
      std::memcpy(&out.data[2 * i], &h, 2);
    } else {  // uint16 counts: 20000 per unit, offset 1000
      const auto u = static_cast<std::uint16_t>(std::lround(1000 + 20000 * std::max(0.0f, values[i])));
      std::memcpy(&out.data[2 * i], &u, 2);
    }
  }
  return out;
}

TEST(BrickedKeep, KeptVoxelsComeBackAsTheyWereAndTheRestAsTheBackgroundMean) {
  const Dims d{40, 36, 70};
  const std::vector<float> field = part_in_air(d, 3);
  for (const SampleType type : {SampleType::Float16, SampleType::UInt16, SampleType::Float32}) {
    SCOPED_TRACE(sample_type_name(type));
    const DenseVolume source = as_samples(field, d, type);
    std::vector<float> values(source.voxel_count());
    for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(source.value(i));
    const float threshold = type == SampleType::UInt16 ? 1500.0f : 0.025f;
    ImportOptions options;
    options.keep = KeepRule{false, threshold, 2};
    options.structure = StructureChoice::Bricked;
    const std::string path = test::temp_path("bricked_keep.ivol");
    const ImportReport report = import_to_ivol(source, path, options);
    EXPECT_EQ(report.structure, "bricked");

    // What the rule should give, computed here.
    const std::vector<std::uint8_t> keep = threshold_keep_mask(values.data(), d, threshold, 2);
    double sum = 0.0;
    std::uint64_t below = 0, kept = 0;
    for (const float v : values)
      if (v < threshold) sum += v, ++below;
    const double mean = sum / static_cast<double>(below);
    double background = mean;
    if (type == SampleType::Float16) background = binary16_to_float(float_to_binary16(static_cast<float>(mean)));
    if (type == SampleType::UInt16) background = std::nearbyint(mean);
    if (type == SampleType::Float32) background = static_cast<float>(mean);
    Reader r(path);
    EXPECT_EQ(r.layout().kind, StructureKind::Bricked);
    const std::vector<float> back = r.read_box(full_box(d));
    double max_error = 0.0;
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (keep[i]) {
        ++kept;
        ASSERT_EQ(back[i], values[i]) << "kept voxel " << i;
      } else {
        ASSERT_EQ(back[i], static_cast<float>(background)) << "voxel " << i << " outside the kept region";
        max_error = std::max(max_error, std::fabs(values[i] - background));
      }
    }
    ASSERT_GT(kept, 0u);
    ASSERT_LT(kept, values.size() / 2);
    EXPECT_FALSE(report.lossless);
    EXPECT_EQ(report.kept_voxels, kept);
    EXPECT_NEAR(report.max_abs_error, max_error, 1e-6 * std::max(1.0, max_error));
    const auto& rule = r.metadata().structure.at("keep");
    EXPECT_EQ(rule.at("outside"), "background");
    EXPECT_EQ(rule.at("background").get<double>(), background);
    EXPECT_EQ(rule.at("kept_voxels").get<std::uint64_t>(), kept);
    EXPECT_EQ(rule.at("margin").get<unsigned>(), 2u);
    EXPECT_FALSE(r.metadata().structure.at("lossless").get<bool>());
    EXPECT_TRUE(check_file(path).ok());

    // The octree of the same rule keeps the same voxels, and an average a
    // coarse leaf elsewhere: a larger file.
    ImportOptions octree = options;
    octree.structure = StructureChoice::Auto;
    const std::string octree_path = test::temp_path("bricked_keep_octree.ivol");
    const ImportReport o = import_to_ivol(source, octree_path, octree);
    EXPECT_EQ(o.structure, "octree");
    Reader ro(octree_path);
    const std::vector<float> octree_back = ro.read_box(full_box(d));
    for (std::size_t i = 0; i < values.size(); ++i)
      if (keep[i]) ASSERT_EQ(octree_back[i], values[i]) << "the octree's kept voxel " << i;
    EXPECT_LT(report.file_bytes, o.file_bytes);
  }
}

// A margin deeper than the volume: the slices read stop at its ends, and the
// kept region still grows by the whole margin across each slice.
TEST(BrickedKeep, AMarginDeeperThanTheVolumeStillGrowsAcrossTheSlices) {
  const Dims d{48, 40, 4};
  std::vector<float> values(voxel_count(d), 0.0f);
  values[(std::size_t{2} * d[1] + 20) * d[0] + 24] = 1.0f;  // one voxel of material
  const DenseVolume source = as_samples(values, d, SampleType::Float32);
  ImportOptions options;
  options.keep = KeepRule{false, 0.5f, 6};
  options.structure = StructureChoice::Bricked;
  const std::string path = test::temp_path("bricked_keep_deep.ivol");
  const ImportReport report = import_to_ivol(source, path, options);
  const std::vector<std::uint8_t> keep = threshold_keep_mask(values.data(), d, 0.5f, 6);
  std::uint64_t kept = 0;
  for (const std::uint8_t k : keep) kept += k;
  EXPECT_EQ(kept, 13u * 13u * 4u);  // 13 x 13 around the voxel, every slice
  EXPECT_EQ(report.kept_voxels, kept);
}

// Otsu's threshold is found as for the octree, and the same threshold goes
// into both files' metadata.
TEST(BrickedKeep, OtsusThresholdIsTheOctreesToo) {
  const Dims d{40, 36, 70};
  const DenseVolume source = as_samples(part_in_air(d, 4), d, SampleType::Float32);
  ImportOptions options;
  options.keep = KeepRule{true, 0.0f, 3};
  options.structure = StructureChoice::Bricked;
  const ImportReport bricked = import_to_ivol(source, test::temp_path("keep_otsu_b.ivol"), options);
  options.structure = StructureChoice::Auto;
  const ImportReport octree = import_to_ivol(source, test::temp_path("keep_otsu_o.ivol"), options);
  EXPECT_EQ(bricked.threshold, octree.threshold);
  EXPECT_GT(bricked.threshold, 0.0f);  // between the air (0) and the part (0.05)
  EXPECT_LT(bricked.threshold, 0.05f);
  EXPECT_EQ(Reader(test::temp_path("keep_otsu_b.ivol")).metadata().structure.at("keep").at("threshold_method"), "otsu");
}

}  // namespace
