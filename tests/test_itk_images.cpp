// ITK's native image files (MetaImage, NRRD) as ivol reads and writes them,
// checked against files written by SimpleITK, pynrrd and RTK themselves
// (tests/data/itk/make_fixtures.py) and the numpy arrays they were made from.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "expect_error.hpp"
#include "hdf5_io.hpp"
#include "itk_image_header.hpp"
#include "itk_image_io.hpp"
#include "itk_image_samples.hpp"
#include "ivol/error.hpp"
#include "projection_io.hpp"
#include "test_support.hpp"

namespace ivol::convert {
namespace {

std::string fixture(const std::string& name) { return std::string(IVOL_SOURCE_DIR) + "/tests/data/itk/" + name; }

// A .npy file as numpy writes it (version 1, C order): its dtype text, its
// shape and its bytes.
struct Npy {
  std::string descr;
  std::vector<std::uint64_t> shape;
  std::vector<std::uint8_t> bytes;
};

Npy load_npy(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all.substr(0, 6), "\x93NUMPY") << path;
  const std::size_t header_length = static_cast<unsigned char>(all[8]) | (static_cast<unsigned char>(all[9]) << 8);
  const std::string header = all.substr(10, header_length);
  Npy npy;
  const std::size_t d = header.find("'descr': '") + 10;
  npy.descr = header.substr(d, header.find('\'', d) - d);
  EXPECT_NE(header.find("'fortran_order': False"), std::string::npos) << header;
  const std::size_t s = header.find("'shape': (") + 10;
  std::string shape = header.substr(s, header.find(')', s) - s);
  for (std::size_t at = 0; at < shape.size();) {
    const std::size_t comma = shape.find(',', at);
    const std::string item = shape.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    if (item.find_first_not_of(' ') != std::string::npos) npy.shape.push_back(std::stoull(item));
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  npy.bytes.assign(all.begin() + static_cast<std::ptrdiff_t>(10 + header_length), all.end());
  return npy;
}

using test::contains;
using test::error_of;

struct VolumeCase {
  const char* file;
  SampleType type;
};

class ItkVolumes : public testing::TestWithParam<VolumeCase> {};

TEST_P(ItkVolumes, ValuesSpacingAndOriginAreThoseItsLibraryWrote) {
  const VolumeCase c = GetParam();
  auto reader = open_itk_image_slabs(fixture(c.file));
  const DenseVolume& shape = reader->shape();
  const std::string stem = std::filesystem::path(c.file).stem().string();
  const Npy expected = load_npy(fixture(stem + ".npy"));
  ASSERT_EQ(expected.shape.size(), 3u);
  EXPECT_EQ(shape.dims,
            (Dims{static_cast<std::uint32_t>(expected.shape[2]), static_cast<std::uint32_t>(expected.shape[1]),
                  static_cast<std::uint32_t>(expected.shape[0])}));
  EXPECT_EQ(shape.type, c.type);
  EXPECT_EQ(shape.voxel_size, (std::array<double, 3>{0.5, 0.25, 2.0}));
  EXPECT_EQ(shape.origin, (std::array<double, 3>{-3.5, 1.25, 10.0}));
  EXPECT_EQ(shape.unit, "mm");
  EXPECT_TRUE(shape.has_geometry);
  EXPECT_FALSE(shape.voxel_size_from.empty());
  std::vector<std::uint8_t> got(static_cast<std::size_t>(shape.voxel_count()) * sample_size(shape.type));
  // In two slabs, the second first: compressed data are read again from
  // the start.
  const std::uint32_t half = shape.dims[2] / 2;
  const std::size_t slice = got.size() / shape.dims[2];
  reader->read(half, shape.dims[2] - half, got.data() + half * slice);
  reader->read(0, half, got.data());
  if (expected.descr == "|i1") {
    // int8 arrives widened to int16.
    ASSERT_EQ(got.size(), expected.bytes.size() * 2);
    for (std::size_t i = 0; i < expected.bytes.size(); ++i) {
      std::int16_t v;
      std::memcpy(&v, got.data() + 2 * i, 2);
      ASSERT_EQ(v, static_cast<std::int8_t>(expected.bytes[i])) << i;
    }
  } else {
    ASSERT_EQ(got.size(), expected.bytes.size()) << expected.descr;
    EXPECT_TRUE(got == expected.bytes) << c.file << ": samples differ from " << stem << ".npy";
  }
}

INSTANTIATE_TEST_SUITE_P(
    Fixtures, ItkVolumes,
    testing::Values(VolumeCase{"u16.mha", SampleType::UInt16}, VolumeCase{"i16_z.mha", SampleType::Int16},
                    VolumeCase{"f32.mhd", SampleType::Float32}, VolumeCase{"u8.nrrd", SampleType::UInt8},
                    VolumeCase{"i8.nrrd", SampleType::Int16}, VolumeCase{"f32_be.nhdr", SampleType::Float32}),
    [](const testing::TestParamInfo<VolumeCase>& info) {
      std::string name = info.param.file;
      for (char& ch : name)
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
      return name;
    });

TEST(ItkImages, ARotatedDirectionIsRefusedNotDropped) {
  const Error e = error_of([] { open_itk_image_slabs(fixture("rotated.mha")); });
  EXPECT_EQ(e.error_class(), ErrorClass::InvalidArgument);
  EXPECT_TRUE(contains(e.what(), "rotated.mha: MetaImage TransformMatrix")) << e.what();
  EXPECT_TRUE(contains(e.what(), "not the identity")) << e.what();
}

// ITK's HDF5 image layout, written by SimpleITK: found without naming the
// dataset, with its spacing and origin, and refused when rotated.
TEST(ItkImages, ItkHdf5ImagesReadWithTheirGeometry) {
  Hdf5SourceInfo source;
  auto reader = open_hdf5_slabs(fixture("u16_itk.h5"), kDefaultDataset, &source);
  const DenseVolume& shape = reader->shape();
  EXPECT_EQ(source.dataset, "/ITKImage/0/VoxelData");
  const Npy expected = load_npy(fixture("u16.npy"));
  EXPECT_EQ(shape.dims,
            (Dims{static_cast<std::uint32_t>(expected.shape[2]), static_cast<std::uint32_t>(expected.shape[1]),
                  static_cast<std::uint32_t>(expected.shape[0])}));
  EXPECT_EQ(shape.type, SampleType::UInt16);
  EXPECT_EQ(shape.voxel_size, (std::array<double, 3>{0.5, 0.25, 2.0}));
  EXPECT_EQ(shape.origin, (std::array<double, 3>{-3.5, 1.25, 10.0}));
  EXPECT_EQ(shape.unit, "mm");
  EXPECT_TRUE(shape.has_geometry);
  EXPECT_TRUE(contains(shape.voxel_size_from, "/ITKImage/0/Spacing")) << shape.voxel_size_from;
  std::vector<std::uint8_t> got(static_cast<std::size_t>(shape.voxel_count()) * 2);
  reader->read(0, shape.dims[2], got.data());
  EXPECT_TRUE(got == expected.bytes);

  const Error e = error_of([] { open_hdf5_slabs(fixture("rotated_itk.h5")); });
  EXPECT_EQ(e.error_class(), ErrorClass::InvalidArgument);
  EXPECT_TRUE(contains(e.what(), "/ITKImage/0/Directions is not the identity")) << e.what();
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void write_file(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

TEST(ItkImages, DamagedFilesAreRefusedNamingTheFileAndWhat) {
  const std::string compressed = read_file(fixture("i16_z.mha"));
  const std::size_t data = compressed.find("ElementDataFile = LOCAL\n") + 24;
  // Cut inside the compressed stream.
  const std::string cut = ivol::test::temp_path("cut.mha");
  write_file(cut, compressed.substr(0, data + (compressed.size() - data) / 2));
  const Error e1 = error_of([&] {
    ImageSamples samples(read_image_header(cut));
    std::vector<std::int16_t> all(12 * 10 * 7);
    samples.read(0, all.size(), all.data());
  });
  EXPECT_TRUE(contains(e1.what(), "cut.mha")) << e1.what();
  EXPECT_TRUE(contains(e1.what(), "CompressedDataSize") || contains(e1.what(), "cut short")) << e1.what();
  // Damaged bytes in the stream.
  std::string damaged = compressed;
  for (std::size_t i = data + 20; i < data + 60; ++i) damaged[i] = static_cast<char>(damaged[i] ^ 0x5a);
  const std::string bad = ivol::test::temp_path("bad.mha");
  write_file(bad, damaged);
  const Error e2 = error_of([&] {
    auto reader = open_itk_image_slabs(bad);
    std::vector<std::int16_t> all(12 * 10 * 7);
    reader->read(0, 7, all.data());
  });
  EXPECT_TRUE(contains(e2.what(), "bad.mha")) << e2.what();
  // Raw samples one byte short.
  const std::string raw = read_file(fixture("u16.mha"));
  const std::string shorter = ivol::test::temp_path("short.mha");
  write_file(shorter, raw.substr(0, raw.size() - 1));
  const Error e3 = error_of([&] { open_itk_image_slabs(shorter); });
  EXPECT_TRUE(contains(e3.what(), "short.mha: 1679 bytes after the MetaImage header's offset")) << e3.what();
  EXPECT_TRUE(contains(e3.what(), "are 1680 bytes")) << e3.what();
  // Sizes whose product overflows, a header without its end.
  const std::string huge = ivol::test::temp_path("huge.mha");
  write_file(huge,
             "NDims = 3\nDimSize = 4294967295 4294967295 4294967295\nElementType = MET_FLOAT\n"
             "ElementDataFile = LOCAL\n");
  EXPECT_EQ(error_of([&] { open_itk_image_slabs(huge); }).error_class(), ErrorClass::LimitExceeded);
  const std::string endless = ivol::test::temp_path("endless.nrrd");
  write_file(endless, "NRRD0004\n" + std::string(2 << 20, '#'));
  EXPECT_TRUE(contains(error_of([&] { open_itk_image_slabs(endless); }).what(), "longer than 1 MiB"));
  const std::string list = ivol::test::temp_path("list.mhd");
  write_file(list, "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\nElementDataFile = LIST\n");
  EXPECT_TRUE(contains(error_of([&] { open_itk_image_slabs(list); }).what(), "several files"));
  const std::string doubles = ivol::test::temp_path("doubles.mha");
  write_file(doubles,
             "NDims = 3\nDimSize = 1 1 1\nElementType = MET_DOUBLE\nElementDataFile = LOCAL\n" + std::string(8, '\0'));
  const Error e4 = error_of([&] { open_itk_image_slabs(doubles); });
  EXPECT_TRUE(contains(e4.what(), "float64 samples")) << e4.what();
}

TEST(ItkImages, WrittenFilesReadBackExactlyWithTheirGeometry) {
  for (const char* name : {"back.mha", "back.nrrd"}) {
    for (SampleType type : {SampleType::UInt8, SampleType::Int16, SampleType::UInt16, SampleType::Float32}) {
      DenseVolume v = make_dense(Dims{5, 4, 3}, type);
      for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<std::uint8_t>(i * 37 + 11);
      v.voxel_size = {0.1, 0.2, 0.30000000000000004};
      v.origin = {-1.0 / 3.0, 2.5, 1e-7};
      v.unit = "mm";
      const std::string path = ivol::test::temp_path(name);
      std::filesystem::remove(path);
      auto writer = create_itk_image_slabs(path, v);
      writer->write(v.data.data(), 2);
      writer->write(v.data.data() + v.data.size() / 3 * 2, 1);
      writer->finish();
      auto reader = open_itk_image_slabs(path);
      EXPECT_EQ(reader->shape().dims, v.dims);
      EXPECT_EQ(reader->shape().type, type);
      EXPECT_EQ(reader->shape().voxel_size, v.voxel_size) << name;
      EXPECT_EQ(reader->shape().origin, v.origin) << name;
      std::vector<std::uint8_t> back(v.data.size());
      reader->read(0, 3, back.data());
      EXPECT_TRUE(back == v.data) << name << " " << sample_type_name(type);
    }
  }
  // Micrometres: MetaImage states millimetres.
  DenseVolume um = make_dense(Dims{2, 2, 2}, SampleType::UInt8);
  um.voxel_size = {5, 5, 10};
  um.unit = "um";
  const std::string path = ivol::test::temp_path("um.mha");
  std::filesystem::remove(path);
  auto writer = create_itk_image_slabs(path, um);
  writer->write(um.data.data(), 2);
  writer->finish();
  EXPECT_TRUE(contains(read_file(path), "ElementSpacing = 0.005 0.005 0.01"));
}

TEST(ItkImages, RtkProjectionsCarryThePitchAndTheOriginOfTheirHeader) {
  ItkImageScan scan = open_itk_image_projections(fixture("rtk/proj.mha"), StoredQuantity::LineIntegrals);
  EXPECT_EQ(scan.projections->columns(), 40);
  EXPECT_EQ(scan.projections->rows(), 30);
  EXPECT_EQ(scan.projections->view_count(), 24u);
  EXPECT_TRUE(scan.has_pitch);
  EXPECT_DOUBLE_EQ(scan.pitch[0], 1.5);
  EXPECT_DOUBLE_EQ(scan.pitch[1], 1.25);
  EXPECT_TRUE(scan.has_origin);
  EXPECT_NEAR(scan.origin[0], -19.5 * 1.5 + 3.0, 1e-12);
  EXPECT_NEAR(scan.origin[1], -14.5 * 1.25 - 2.0, 1e-12);
  // Rows of a late view, then an early one (the samples were inflated once).
  std::vector<float> late(2 * 40), early(40);
  scan.projections->read_rows(20, 10, 12, late.data());
  scan.projections->read_rows(0, 15, 16, early.data());
  float peak = 0;
  for (float v : early) peak = std::max(peak, v);
  EXPECT_GT(peak, 0.0f) << "the central row of view 0 crosses the phantom";
}

}  // namespace
}  // namespace ivol::convert
