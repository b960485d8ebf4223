// The exactness contract of the converters (tools/convert/exactness.hpp):
// lossless paths keep every bit (-0 and NaN payloads included), and what a
// target type does not hold is counted, never silently rounded or clamped.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>

#include "dense_volume.hpp"
#include "exactness.hpp"
#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "ivol_io.hpp"
#include "test_support.hpp"
#include "vdb_io.hpp"

namespace {

using namespace ivol;
using namespace ivol::convert;

template <typename T>
DenseVolume volume_of(const Dims& dims, SampleType type, const std::vector<T>& values) {
  DenseVolume v = make_dense(dims, type);
  EXPECT_EQ(values.size() * sizeof(T), v.data.size());
  std::memcpy(v.data.data(), values.data(), v.data.size());
  return v;
}

float float_of(std::uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

std::uint32_t bits_of(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

TEST(Exactness, Binary16KeepNanIsTheIdentityThroughFloat) {
  for (std::uint32_t b = 0; b < 0x10000; ++b) {
    const auto h = static_cast<std::uint16_t>(b);
    ASSERT_EQ(float_to_binary16_keep_nan(binary16_to_float(h)), h) << std::hex << b;
  }
  EXPECT_EQ(float_to_binary16_keep_nan(float_of(0x7F800001u)), 0x7E00);  // payload below binary16's: quiet NaN
  EXPECT_EQ(float_to_binary16_keep_nan(1.0f / 3.0f), float_to_binary16(1.0f / 3.0f));
}

// Spec §9: a leaf keeps any bits. A binary16 source imported losslessly (the
// default for f16) gives back every bit pattern, -0 and NaN payloads
// included; before, the import stored every NaN as 0x7E00 and the export
// (0 + 1 x -0) turned -0 into +0.
TEST(Exactness, F16ImportKeepsNegativeZeroAndNanPayloads) {
  const Dims dims{5, 4, 3};
  std::vector<std::uint16_t> bits(voxel_count(dims));
  for (std::size_t i = 0; i < bits.size(); ++i) bits[i] = float_to_binary16(static_cast<float>(i) * 0.25f - 3.0f);
  // A whole octant of -0 (it may merge into one leaf, which must keep -0),
  // -0 next to +0, NaNs with payloads (a signalling one too), infinities.
  for (std::uint32_t z = 0; z < 2; ++z)
    for (std::uint32_t y = 0; y < 2; ++y)
      for (std::uint32_t x = 0; x < 2; ++x) bits[(z * 4 + y) * 5 + x] = 0x8000;
  const std::vector<std::uint16_t> special{0x8000, 0x0000, 0x7D01, 0xFE05, 0x7E00, 0x7FFF, 0x7C00, 0xFC00, 0x0001};
  for (std::size_t n = 0; n < special.size(); ++n) bits[30 + n] = special[n];
  const DenseVolume source = volume_of(dims, SampleType::Float16, bits);
  // Both structures: the bricked grid (the default for f16 since codec 3)
  // and the octree.
  for (const StructureChoice structure : {StructureChoice::Auto, StructureChoice::Octree}) {
    const std::string path = test::temp_path("f16-bits.ivol");
    ImportOptions options;
    options.structure = structure;
    const ImportReport report = import_to_ivol(source, path, options);
    EXPECT_EQ(report.structure, structure == StructureChoice::Auto ? "bricked" : "octree");
    EXPECT_TRUE(report.lossless);
    EXPECT_TRUE(report.encoding_loss.exact());

    Reader reader(path);
    const std::vector<std::uint8_t> stored = reader.read_box_bits(full_box(dims));
    ASSERT_EQ(stored.size(), source.data.size());
    for (std::size_t i = 0; i < bits.size(); ++i)
      ASSERT_EQ(stored[2 * i] | (stored[2 * i + 1] << 8), bits[i]) << "stored bits of voxel " << i;
    const DenseVolume back = export_from_ivol(reader, Box{}, 0, SampleType::Float16);
    EXPECT_EQ(back.data, source.data);
    EXPECT_TRUE(std::signbit(reader.read_box(full_box(dims))[0])) << "Reader::read_box keeps -0";
    EXPECT_EQ(natural_sample_type(reader), SampleType::Float16);
    EXPECT_EQ(natural_float_type(reader), SampleType::Float16);
  }
}

// With a keep rule, a node without kept voxels becomes one leaf: its value
// when the voxels are uniform, else their mean (reported as coarsened). -0 and
// +0 compare equal, but a region holding both is not uniform: before, it
// became a leaf of one sign and the build called itself lossless.
TEST(Exactness, CoarseningTellsNegativeFromPositiveZero) {
  const Dims dims{4, 4, 4};
  const std::vector<std::uint8_t> keep(voxel_count(dims), 0);
  BuildOptions options;
  options.encoding = ValueEncoding::Float32;
  options.keep_mask = keep.data();
  std::vector<float> mixed(voxel_count(dims), 0.0f);
  mixed[5] = -0.0f;
  EXPECT_FALSE(build_octree(mixed.data(), dims, options).lossless);
  const std::vector<float> negative(voxel_count(dims), -0.0f);
  const BuildResult all = build_octree(negative.data(), dims, options);
  EXPECT_TRUE(all.lossless);
  const std::string path = test::temp_path("negative-zero.ivol");
  write_octree(all.octree, Metadata{}, path);
  Reader reader(path);
  EXPECT_EQ(reader.voxel_bits(3, 2, 1), 0x80000000u);
}

TEST(Exactness, IntegerTargetsCountWhatTheyDoNotHold) {
  VolumeLayout layout;
  layout.encoding = ValueEncoding::Float32;
  const std::vector<float> values{0.0f, 1.0f, 255.0f, 2.5f, -1.0f, 300.0f, std::nanf(""), -0.0f};
  std::vector<std::uint8_t> stored(values.size() * 4);
  std::memcpy(stored.data(), values.data(), stored.size());
  std::vector<std::uint8_t> out(values.size());
  LossTally loss;
  stored_to_samples(layout, stored.data(), values.size(), SampleType::UInt8, out.data(), loss);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{0, 1, 255, 2, 0, 255, 0, 0}));
  EXPECT_EQ(loss.voxels, 4u);  // 2.5 rounds, -1 and 300 do not fit, NaN; -0 is 0
  EXPECT_EQ(loss.out_of_range, 2u);
  EXPECT_EQ(loss.lowest, -1.0);
  EXPECT_EQ(loss.highest, 300.0);
  EXPECT_EQ(loss.nans, 1u);
  EXPECT_EQ(loss.max_error, 45.0);
  const std::string text = describe_loss(loss, values.size(), "u8");
  EXPECT_NE(text.find("4 of 8 voxels change (largest error 45"), std::string::npos) << text;
  EXPECT_NE(text.find("2 values in [-1, 300] do not fit in u8"), std::string::npos) << text;
  try {
    refuse_loss(loss, values.size(), "a.ivol -> b.raw as u8", "u8", "--out-type f32");
    FAIL() << "not refused";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::InvalidArgument);
    EXPECT_NE(std::string(e.what()).find("--out-type f32 is exact; --allow-lossy accepts the loss"), std::string::npos)
        << e.what();
  }

  // Integers held as float32 go to u8 exactly.
  const std::vector<float> integers{0.0f, 7.0f, 128.0f, 255.0f};
  std::memcpy(stored.data(), integers.data(), 16);
  LossTally none;
  stored_to_samples(layout, stored.data(), integers.size(), SampleType::UInt8, out.data(), none);
  EXPECT_TRUE(none.exact());
  EXPECT_EQ(std::vector<std::uint8_t>(out.begin(), out.begin() + 4), (std::vector<std::uint8_t>{0, 7, 128, 255}));
}

TEST(Exactness, Uint16CodesWithScaleAndOffset) {
  VolumeLayout layout;
  layout.encoding = ValueEncoding::UInt16;
  layout.value_offset = -1000.0;
  const std::vector<std::uint16_t> codes{0, 999, 1000, 65535};
  std::vector<std::uint8_t> stored(8);
  std::memcpy(stored.data(), codes.data(), 8);
  std::vector<std::uint8_t> out(8);
  LossTally u16;
  stored_to_samples(layout, stored.data(), 4, SampleType::UInt16, out.data(), u16);
  EXPECT_EQ(u16.out_of_range, 2u);  // -1000 and -1 are negative
  EXPECT_EQ(u16.lowest, -1000.0);
  EXPECT_EQ(u16.highest, -1.0);
  std::vector<std::uint8_t> f32(16);
  LossTally exact;
  stored_to_samples(layout, stored.data(), 4, SampleType::Float32, f32.data(), exact);
  EXPECT_TRUE(exact.exact());
  // A scale whose products are not float32 numbers is not exact as f32.
  layout.value_offset = 0.0;
  layout.value_scale = 0.1;
  LossTally rounded;
  stored_to_samples(layout, stored.data(), 4, SampleType::Float32, f32.data(), rounded);
  EXPECT_EQ(rounded.voxels, 1u);  // 999 x 0.1; 100 and 6553.5 are float32 numbers
  EXPECT_GT(rounded.max_error, 0.0);
}

TEST(Exactness, DefaultTypesHoldTheSourceValues) {
  const Dims dims{4, 4, 4};
  struct Case {
    SampleType type;
    SampleType natural;
    SampleType natural_float;
  };
  for (const Case c : {Case{SampleType::UInt8, SampleType::UInt8, SampleType::Float32},
                       Case{SampleType::UInt16, SampleType::UInt16, SampleType::Float32},
                       Case{SampleType::Int16, SampleType::Int16, SampleType::Float32},
                       Case{SampleType::Float32, SampleType::Float32, SampleType::Float32}}) {
    DenseVolume v = make_dense(dims, c.type);
    for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<std::uint8_t>(i * 37);
    if (c.type == SampleType::Float32)
      for (std::size_t i = 0; i < v.voxel_count(); ++i) {
        const float f = static_cast<float>(i) / 3.0f;
        std::memcpy(&v.data[4 * i], &f, 4);
      }
    const std::string path = test::temp_path(std::string("natural-") + sample_type_name(c.type) + ".ivol");
    import_to_ivol(v, path, ImportOptions{});
    Reader reader(path);
    EXPECT_EQ(natural_sample_type(reader), c.natural) << sample_type_name(c.type);
    EXPECT_EQ(natural_float_type(reader), c.natural_float) << sample_type_name(c.type);
    const DenseVolume back = export_from_ivol(reader, Box{}, 0, c.natural);
    EXPECT_EQ(back.data, v.data) << sample_type_name(c.type);
  }
}

TEST(Exactness, ImportRefusesLossyEncodingUnlessAllowed) {
  const Dims dims{4, 4, 4};
  std::vector<float> values(voxel_count(dims));
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i) * 0.001f;
  const DenseVolume v = volume_of(dims, SampleType::Float32, values);
  ImportOptions options;
  options.encoding = ValueEncoding::Binary16;
  options.allow_lossy = false;
  const std::string path = test::temp_path("refused.ivol");
  std::filesystem::remove(path);
  EXPECT_THROW(import_to_ivol(v, path, options), Error);
  EXPECT_FALSE(std::filesystem::exists(path));
  options.allow_lossy = true;
  const ImportReport r = import_to_ivol(v, path, options);
  EXPECT_GT(r.encoding_loss.voxels, 0u);
  EXPECT_GT(r.encoding_loss.max_error, 0.0);
  EXPECT_FALSE(r.lossless);
}

TEST(Exactness, VdbGridKeepsNegativeZeroAndNans) {
  const Dims dims{4, 3, 2};
  std::vector<float> values(voxel_count(dims));
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i) + 0.5f;
  values[1] = -0.0f;
  values[2] = float_of(0x7FC00123u);
  values[3] = float_of(0xFF800001u);
  values[4] = 0.0f;  // the background: stays inactive, reads back as itself
  const DenseVolume v = volume_of(dims, SampleType::Float32, values);
  const std::string path = test::temp_path("bits.vdb");
  const LossTally loss = write_vdb(v, path, 0.0f, "density", /*half=*/false);
  EXPECT_TRUE(loss.exact()) << describe_loss(loss, values.size(), "float32");
  const VdbVolume back = read_vdb(path);
  ASSERT_EQ(back.volume.dims, dims);
  for (std::size_t i = 0; i < values.size(); ++i) {
    float got;
    std::memcpy(&got, &back.volume.data[4 * i], 4);
    EXPECT_EQ(bits_of(got), bits_of(values[i])) << "voxel " << i;
  }
  // As a half-float grid 0.5 steps are exact, 1/3 is not: counted, and refused by the check.
  values[5] = 1.0f / 3.0f;
  const DenseVolume w = volume_of(dims, SampleType::Float32, values);
  const std::string half_path = test::temp_path("half.vdb");
  std::filesystem::remove(half_path);
  EXPECT_THROW(write_vdb(w, half_path, 0.0f, "density", true,
                         [&](const LossTally& l) { refuse_loss(l, values.size(), half_path, "f16"); }),
               Error);
  EXPECT_FALSE(std::filesystem::exists(half_path));
}

}  // namespace
