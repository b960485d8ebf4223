// Raw and TIFF converters and the .ivol import/export, against files written
// by another implementation (tifffile, which wraps its own TIFF codecs, and
// plain byte writing) and read back by it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "bricked_import.hpp"
#include "dense_volume.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol_io.hpp"
#include "raw_io.hpp"
#include "test_support.hpp"
#include "tiff_io.hpp"

namespace {

using namespace ivol;
using namespace ivol::convert;

int python(const std::string& script) {
  const std::string path = test::temp_path("script.py");
  test::write_bytes(path, std::vector<std::uint8_t>(script.begin(), script.end()));
  return std::system((std::string(IVOL_PYTHON) + " " + path).c_str());
}

// The values the Python scripts write: v(x, y, z) = (x + 3y + 7z) mod m.
double formula(std::uint32_t x, std::uint32_t y, std::uint32_t z, double modulus) {
  return std::fmod(x + 3.0 * y + 7.0 * z, modulus);
}

void expect_formula(const DenseVolume& v, double modulus, double scale = 1.0) {
  for (std::uint32_t z = 0; z < v.dims[2]; ++z)
    for (std::uint32_t y = 0; y < v.dims[1]; ++y)
      for (std::uint32_t x = 0; x < v.dims[0]; ++x)
        ASSERT_EQ(v.value((std::uint64_t{z} * v.dims[1] + y) * v.dims[0] + x), formula(x, y, z, modulus) * scale)
            << x << "," << y << "," << z;
}

TEST(Raw, RoundTripInBothByteOrders) {
  DenseVolume v = make_dense({5, 4, 3}, SampleType::Int16);
  for (std::uint64_t i = 0; i < v.voxel_count(); ++i) {
    const auto s = static_cast<std::int16_t>(i * 997 - 30000);
    std::memcpy(&v.data[2 * i], &s, 2);
  }
  for (bool big : {false, true}) {
    const std::string path = test::temp_path(big ? "big.raw" : "little.raw");
    write_raw(v, path, big);
    RawLayout layout{{5, 4, 3}, SampleType::Int16, big, 0};
    EXPECT_EQ(read_raw(path, layout).data, v.data);
  }
  // Big-endian bytes are really big-endian.
  const auto bytes = test::read_bytes(test::temp_path("big.raw"));
  EXPECT_EQ(bytes[0], 0x8A);  // -30000 = 0x8AD0
  EXPECT_EQ(bytes[1], 0xD0);
}

TEST(Raw, HeaderBytesAndSizeCheck) {
  std::vector<std::uint8_t> bytes(16 + 2 * 8, 0);
  for (int i = 0; i < 8; ++i) bytes[16 + 2 * i] = static_cast<std::uint8_t>(i);
  const std::string path = test::temp_path("header.raw");
  test::write_bytes(path, bytes);
  const DenseVolume v = read_raw(path, RawLayout{{2, 2, 2}, SampleType::UInt16, false, 16});
  EXPECT_EQ(v.value(7), 7.0);
  try {
    read_raw(path, RawLayout{{2, 2, 3}, SampleType::UInt16, false, 16});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("has 32 bytes"), std::string::npos) << e.what();
  }
}

TEST(Tiff, ReadsStacksWrittenByTifffile) {
  const std::string dir = test::temp_dir();
  ASSERT_EQ(python("import numpy as np, tifffile, os\n"
                   "z, y, x = np.mgrid[0:6, 0:37, 0:41]\n"
                   "v = (x + 3*y + 7*z)\n"
                   "d = '" +
                   dir +
                   "'\n"
                   "tifffile.imwrite(d + '/u16_deflate.tif', (v % 60000).astype(np.uint16), compression='zlib')\n"
                   "tifffile.imwrite(d + '/u8_plain.tif', (v % 256).astype(np.uint8))\n"
                   "tifffile.imwrite(d + '/f32_tiled.tif', (v % 1000).astype(np.float32) * 0.5, tile=(16, 16))\n"
                   "tifffile.imwrite(d + '/i16_plain.tif', (v % 1000).astype(np.int16) - 500)\n"
                   "os.makedirs(d + '/folder', exist_ok=True)\n"
                   "for k in range(6):\n"
                   "    tifffile.imwrite(d + '/folder/slice%d.tif' % k, (v[k] % 60000).astype(np.uint16))\n"),
            0);
  const DenseVolume u16 = read_tiff(dir + "/u16_deflate.tif");
  EXPECT_EQ(u16.dims, (Dims{41, 37, 6}));
  EXPECT_EQ(u16.type, SampleType::UInt16);
  expect_formula(u16, 60000);
  // LZW, and tiles, by libtiff's own tiffcp (tifffile here has no LZW codec).
  ASSERT_EQ(std::system(("tiffcp -c lzw " + dir + "/u8_plain.tif " + dir + "/u8_lzw.tif").c_str()), 0);
  ASSERT_EQ(std::system(("tiffcp -c zip -t -w 16 -l 16 " + dir + "/u16_deflate.tif " + dir + "/u16_tiled.tif").c_str()),
            0);
  EXPECT_EQ(read_tiff(dir + "/u16_tiled.tif").data, u16.data);
  const DenseVolume u8 = read_tiff(dir + "/u8_lzw.tif");
  EXPECT_EQ(u8.type, SampleType::UInt8);
  expect_formula(u8, 256);
  const DenseVolume f32 = read_tiff(dir + "/f32_tiled.tif");
  EXPECT_EQ(f32.type, SampleType::Float32);
  expect_formula(f32, 1000, 0.5);
  const DenseVolume i16 = read_tiff(dir + "/i16_plain.tif");
  EXPECT_EQ(i16.type, SampleType::Int16);
  EXPECT_EQ(i16.value(0), -500.0);
  // slice10 does not exist, but slice2 must come before slice10-like names:
  // here names slice0..slice5 sort naturally.
  const DenseVolume folder = read_tiff(dir + "/folder");
  EXPECT_EQ(folder.data, u16.data);
}

TEST(Tiff, NaturalOrderOfSliceNames) {
  const std::string dir = test::temp_path("natural");
  std::filesystem::create_directories(dir);
  for (const char* name : {"s10.tif", "s2.tif", "s1.tif", "s002b.tif", "notes.txt"})
    test::write_bytes(dir + "/" + name, {});
  EXPECT_EQ(natural_sorted_files(dir), (std::vector<std::string>{"s1.tif", "s2.tif", "s002b.tif", "s10.tif"}));
}

TEST(Tiff, WrittenStacksReadByTifffile) {
  DenseVolume v = make_dense({23, 17, 5}, SampleType::Float32);
  for (std::uint32_t z = 0; z < 5; ++z)
    for (std::uint32_t y = 0; y < 17; ++y)
      for (std::uint32_t x = 0; x < 23; ++x) {
        const auto f = static_cast<float>(formula(x, y, z, 1000) * 0.25);
        std::memcpy(&v.data[4 * ((z * 17 + y) * 23 + x)], &f, 4);
      }
  const std::string path = test::temp_path("ours.tif");
  write_tiff(v, path);
  EXPECT_EQ(read_tiff(path).data, v.data);
  DenseVolume ints = make_dense({23, 17, 5}, SampleType::UInt16);
  for (std::uint64_t i = 0; i < ints.voxel_count(); ++i) {
    const auto s = static_cast<std::uint16_t>(v.value(i) * 4);
    std::memcpy(&ints.data[2 * i], &s, 2);
  }
  write_tiff(ints, test::temp_path("ours16.tif"));
  EXPECT_EQ(python("import numpy as np, tifffile\n"
                   "a = tifffile.imread('" +
                   test::temp_path("ours16.tif") +
                   "')\n"
                   "z, y, x = np.mgrid[0:5, 0:17, 0:23]\n"
                   "assert a.dtype == np.uint16 and (a == (x + 3*y + 7*z) % 1000).all()\n"),
            0);
  EXPECT_EQ(python("import numpy as np, tifffile\n"
                   "t = tifffile.TiffFile('" +
                   path +
                   "')\n"
                   "a = t.asarray()\n"
                   "z, y, x = np.mgrid[0:5, 0:17, 0:23]\n"
                   "assert a.shape == (5, 17, 23), a.shape\n"
                   "assert a.dtype == np.float32\n"
                   "assert (a == ((x + 3*y + 7*z) % 1000) * 0.25).all()\n"
                   "assert t.pages[0].compression == 8, t.pages[0].compression  # deflate\n"),
            0);
}

TEST(Tiff, RefusesWhatItCannotHold) {
  const std::string path = test::temp_path("rgb.tif");
  ASSERT_EQ(python("import numpy as np, tifffile\n"
                   "tifffile.imwrite('" +
                   path + "', np.zeros((4, 5, 3), np.uint8), photometric='rgb')\n"),
            0);
  try {
    read_tiff(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("samples per pixel"), std::string::npos) << e.what();
  }
  test::write_bytes(test::temp_path("not.tif"), {'h', 'i'});
  EXPECT_THROW(read_tiff(test::temp_path("not.tif")), Error);
}

TEST(IvolImport, LosslessForEveryIntegerTypeAndExportBack) {
  for (SampleType type : {SampleType::UInt8, SampleType::UInt16, SampleType::Int16, SampleType::Float32}) {
    DenseVolume v = make_dense({9, 8, 7}, type);
    for (std::uint64_t i = 0; i < v.voxel_count(); ++i) {
      const double value =
          (i % 13 < 6) ? 100.0 : static_cast<double>((i * 37) % 200) - (type == SampleType::Int16 ? 100 : 0);
      std::uint8_t* p = &v.data[i * sample_size(type)];
      if (type == SampleType::UInt8) *p = static_cast<std::uint8_t>(value);
      if (type == SampleType::UInt16) {
        const auto s = static_cast<std::uint16_t>(value);
        std::memcpy(p, &s, 2);
      }
      if (type == SampleType::Int16) {
        const auto s = static_cast<std::int16_t>(value);
        std::memcpy(p, &s, 2);
      }
      if (type == SampleType::Float32) {
        const auto s = static_cast<float>(value) * 0.125f;
        std::memcpy(p, &s, 4);
      }
    }
    v.voxel_size = {0.5, 0.5, 0.75};
    v.has_geometry = true;
    const std::string path = test::temp_path("import.ivol");
    const ImportReport r = import_to_ivol(v, path, ImportOptions{});
    EXPECT_TRUE(r.lossless) << sample_type_name(type);
    Reader reader(path);
    EXPECT_EQ(reader.metadata().voxel_size[2], 0.75);
    const DenseVolume back = export_from_ivol(reader, Box{}, 0, type);
    EXPECT_EQ(back.data, v.data) << sample_type_name(type);
  }
}

TEST(IvolImport, KeepRuleParsing) {
  const KeepRule a = parse_keep_rule("threshold=0.5,margin=3");
  EXPECT_FALSE(a.otsu);
  EXPECT_EQ(a.threshold, 0.5f);
  EXPECT_EQ(a.margin, 3u);
  EXPECT_TRUE(parse_keep_rule("threshold=otsu").otsu);
  EXPECT_THROW(parse_keep_rule("margin=3"), Error);
  EXPECT_THROW(parse_keep_rule("threshold=abc"), Error);
  EXPECT_THROW(parse_keep_rule("threshold=1,colour=red"), Error);
}

}  // namespace

namespace {

using namespace ivol;
using namespace ivol::convert;

// StructureChoice::Auto (issue 22): lossless every-voxel uint16 becomes a
// bricked grid, read back bit for bit; where a layer of bricks (32 slices)
// would exceed the memory budget and the octree writer's slabs (8 slices)
// do not, the octree is chosen and the reason given.
TEST(Converters, AutoStructureChoosesBrickedGridsWithinTheMemoryBudget) {
  DenseVolume v = make_dense({64, 64, 64}, SampleType::UInt16);
  for (std::size_t i = 0; i < v.data.size() / 2; ++i) {
    const auto value = static_cast<std::uint16_t>(1000 + (i % 64) * 3 + (i / 64 % 64) * 5 + (i / 4096) * 7);
    std::memcpy(v.data.data() + 2 * i, &value, 2);
  }
  ImportOptions options;
  const std::string path = test::temp_path("auto.ivol");
  ImportReport report = import_to_ivol(v, path, options);
  EXPECT_EQ(report.structure, "bricked");
  EXPECT_NE(report.structure_reason.find("every voxel kept, as 16-bit"), std::string::npos);
  {
    Reader reader(path);
    EXPECT_EQ(reader.layout().kind, StructureKind::Bricked);
    EXPECT_EQ(reader.read_box_bits(full_box({64, 64, 64})), v.data);
    EXPECT_EQ(reader.metadata().structure.value("kind", ""), "bricked");
  }
  options.slab_budget_bytes = 8 * 64 * 64 * 4;  // octree slabs of 8 slices
  options.memory_bytes = 500 * 1024;            // a layer of 32 slices needs 768 KiB
  const std::string small = test::temp_path("auto_small.ivol");
  report = import_to_ivol(v, small, options);
  EXPECT_EQ(report.structure, "octree");
  EXPECT_NE(report.structure_reason.find("exceeds the memory budget"), std::string::npos) << report.structure_reason;
  Reader reader(small);
  EXPECT_EQ(reader.layout().kind, StructureKind::Octree);
  EXPECT_EQ(reader.read_box_bits(full_box({64, 64, 64})), v.data);
}

// However a bricked grid's samples are read (several whole layers at once,
// one layer, or parts of one, as the budget allows: bricked_read_slices),
// the writer sees the same layers, so the file is the same.
TEST(Converters, BrickedFileDoesNotDependOnHowItsSamplesAreRead) {
  DenseVolume v = make_dense({64, 48, 80}, SampleType::UInt16);  // layers of 32, 32 and 16 slices
  for (std::size_t i = 0; i < v.data.size() / 2; ++i) {
    const auto value = static_cast<std::uint16_t>(1000 + (i * 2654435761U >> 20) % 97 + (i / 3072) * 7);
    std::memcpy(v.data.data() + 2 * i, &value, 2);
  }
  std::vector<std::uint8_t> first;
  for (const std::uint32_t slices : {96U, 64U, 32U, 8U, 1U}) {
    ImportOptions options;
    options.memory_bytes = bricked_layer_bytes(v, options, ValueEncoding::UInt16, slices);
    ASSERT_EQ(bricked_read_slices(v, options, ValueEncoding::UInt16), slices);
    // A source whose thicker reads do not pay (a raw file, TIFF pages) is
    // read a layer of 32 slices at a time whatever the budget.
    EXPECT_EQ(bricked_read_slices(v, options, ValueEncoding::UInt16, false), std::min(slices, 32U));
    const std::string path = test::temp_path("read_" + std::to_string(slices) + ".ivol");
    EXPECT_EQ(import_to_ivol(v, path, options).structure, "bricked") << slices;
    const std::vector<std::uint8_t> bytes = test::read_bytes(path);
    if (first.empty()) {
      first = bytes;
      EXPECT_EQ(Reader(path).read_box_bits(full_box({64, 48, 80})), v.data);
    } else {
      EXPECT_EQ(bytes, first) << "read " << slices << " slices at a time";
    }
  }
}

}  // namespace
