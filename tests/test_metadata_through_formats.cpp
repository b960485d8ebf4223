// The parsers and rules behind geometry through the formats, case by case:
// the ImageJ and OME-XML descriptions, unit spellings, ivol's tag 65369, and
// the TIFF folder rules. The libraries on the other side (tifffile, h5py,
// pyopenvdb) are checked by metadata_through_formats.py.
#include <gtest/gtest.h>
#include <tiffio.h>

#include <filesystem>
#include <fstream>
#include <functional>

#include "ivol/error.hpp"
#include "test_support.hpp"
#include "tiff_folder.hpp"
#include "tiff_io.hpp"
#include "tiff_metadata.hpp"
#include "volume_metadata.hpp"

using namespace ivol::convert;

namespace {

std::string fresh_dir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/ivol_meta_" + name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

void touch(const std::string& path) { std::ofstream(path) << "x"; }

ivol::ErrorClass error_of(const std::function<void()>& f, std::string* message = nullptr) {
  try {
    f();
  } catch (const ivol::Error& e) {
    if (message) *message = e.what();
    return e.error_class();
  }
  ADD_FAILURE() << "no ivol::Error";
  return ivol::ErrorClass::InvalidArgument;
}

}  // namespace

TEST(ImageJDescription, ParsesUnitSpacingAndOrigin) {
  const ImageJDescription d =
      parse_imagej_description("ImageJ=1.54f\nimages=10\nslices=10\nunit=micron\nspacing=2.5\nxorigin=4\nloop=false\n");
  EXPECT_TRUE(d.is_imagej);
  EXPECT_EQ(d.unit, "micron");
  ASSERT_TRUE(d.spacing);
  EXPECT_DOUBLE_EQ(*d.spacing, 2.5);
  ASSERT_TRUE(d.origin_pixels[0]);
  EXPECT_DOUBLE_EQ(*d.origin_pixels[0], 4.0);
  EXPECT_FALSE(d.origin_pixels[1]);
  EXPECT_FALSE(parse_imagej_description("spacing=2\n").is_imagej);            // not ImageJ's
  EXPECT_FALSE(parse_imagej_description("ImageJ=1\nspacing=nan\n").spacing);  // not a number
}

TEST(ImageJDescription, WritesWhatItReads) {
  DenseVolume v;
  v.has_geometry = true;
  v.voxel_size = {0.5, 0.5, 0.25};
  v.origin = {-1.0, 2.0, 0.5};
  v.unit = "mm";
  const ImageJDescription d = parse_imagej_description(imagej_description(v, 7));
  ASSERT_TRUE(d.is_imagej && d.spacing);
  EXPECT_EQ(d.unit, "mm");
  EXPECT_DOUBLE_EQ(*d.spacing, 0.25);
  // ImageJ's x of pixel i is (i - xorigin) * width: origin = -xorigin * width.
  for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(-*d.origin_pixels[a] * v.voxel_size[a], v.origin[a]);
  v.has_geometry = false;
  EXPECT_EQ(imagej_description(v, 7).find("unit="), std::string::npos);  // uncalibrated: claims nothing
}

TEST(OmeXml, PhysicalSizesWithPrefixAndDefaultUnit) {
  const std::string xml =
      "<?xml version=\"1.0\"?><ome:OME xmlns:ome=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\">"
      "<ome:Image ID=\"Image:0\"><ome:Pixels PhysicalSizeX=\"0.65\" PhysicalSizeY=\"0.65\" PhysicalSizeZ=\"2\" "
      "PhysicalSizeZUnit=\"mm\"/></ome:Image></ome:OME>";
  const OmePhysicalSize o = parse_ome_xml(xml, "x.tif");
  ASSERT_TRUE(o.is_ome);
  ASSERT_TRUE(o.size[0] && o.size[2]);
  EXPECT_DOUBLE_EQ(*o.size[0], 0.65);
  EXPECT_EQ(normalise_length_unit(o.unit[0]), "um");  // OME's default
  EXPECT_EQ(o.unit[2], "mm");
  EXPECT_FALSE(parse_ome_xml("<svg/>", "x.tif").is_ome);
  EXPECT_FALSE(parse_ome_xml("ImageJ=1.54f", "x.tif").is_ome);
  std::string message;
  EXPECT_EQ(
      error_of([] { parse_ome_xml("<OME><Image><Pixels PhysicalSizeX=\"-1\"/></Image></OME>", "x.tif"); }, &message),
      ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find("x.tif: OME PhysicalSizeX '-1'"), std::string::npos) << message;
}

TEST(LengthUnits, SpellingsAndFactors) {
  for (const char* um : {"um", "micron", "microns", "\u00b5m", "\u03bcm", "\\u00B5m", "micrometre"})
    EXPECT_EQ(normalise_length_unit(um), "um") << um;
  EXPECT_EQ(normalise_length_unit("pixel"), "");
  EXPECT_EQ(normalise_length_unit("furlong"), "furlong");
  EXPECT_DOUBLE_EQ(length_unit_factor("um", "mm"), 1e-3);
  EXPECT_DOUBLE_EQ(length_unit_factor("m", "mm"), 1e3);
  EXPECT_EQ(length_unit_factor("furlong", "mm"), 0.0);
}

TEST(IvolTag, RoundTripsAndRefusesGarbage) {
  const std::string dir = fresh_dir("tag");
  DenseVolume v = make_dense({3, 2, 2}, SampleType::UInt16);
  v.has_geometry = true;
  v.voxel_size = {0.1, 0.2, 0.3};
  v.origin = {1, 2, 3};
  v.unit = "um";
  v.quantity = "density";
  v.value_unit = "g/cm\u00b3";  // not ASCII: escaped in the ASCII tag
  v.provenance = R"({"created":"2026-01-01T00:00:00Z"})";
  write_tiff(v, dir + "/v.tif");
  const DenseVolume back = read_tiff(dir + "/v.tif");
  EXPECT_TRUE(back.has_geometry);
  EXPECT_EQ(back.voxel_size, v.voxel_size);
  EXPECT_EQ(back.origin, v.origin);
  EXPECT_EQ(back.unit, "um");
  EXPECT_EQ(back.quantity, "density");
  EXPECT_EQ(back.value_unit, v.value_unit);
  EXPECT_EQ(nlohmann::json::parse(back.provenance), nlohmann::json::parse(v.provenance));

  // A tag 65369 that is not JSON is refused, naming the file.
  register_ivol_tiff_tag();
  TIFF* tif = TIFFOpen((dir + "/bad.tif").c_str(), "w");
  ASSERT_TRUE(tif);
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, 1u);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, 1u);
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 8);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
  TIFFSetField(tif, kIvolMetadataTag, "{not json");
  unsigned char pixel = 0;
  TIFFWriteScanline(tif, &pixel, 0, 0);
  TIFFClose(tif);
  std::string message;
  EXPECT_EQ(error_of([&] { read_tiff(dir + "/bad.tif"); }, &message), ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find("bad.tif: tag 65369"), std::string::npos) << message;
}

TEST(TiffFolder, NumberingRules) {
  const std::string dir = fresh_dir("folder");
  for (const char* name : {"a_010.tif", "a_012.tif", "a_014.tif", "._a_010.tif", ".DS_Store", "notes.txt"})
    touch(dir + "/" + name);
  const TiffFolder ok = scan_tiff_folder(dir);  // a step of 2 is no gap
  ASSERT_EQ(ok.files.size(), 3u);
  EXPECT_EQ(ok.files[0], dir + "/a_010.tif");
  EXPECT_EQ(ok.files[2], dir + "/a_014.tif");
  ASSERT_EQ(ok.notes.size(), 1u);
  EXPECT_NE(ok.notes[0].find(".DS_Store, ._a_010.tif"), std::string::npos) << ok.notes[0];

  touch(dir + "/a_011.tif");
  touch(dir + "/a_015.tif");
  touch(dir + "/a_018.tif");  // now step 1: 013 and 016 .. 017 missing
  std::string message;
  EXPECT_EQ(error_of([&] { scan_tiff_folder(dir); }, &message), ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find(dir + "/a_014.tif follows a_012.tif: a_013.tif is missing (and 1 more gap); use --allow-gaps"),
            std::string::npos)
      << message;
  const TiffFolder gaps = scan_tiff_folder(dir, TiffFolderOptions{true});
  EXPECT_EQ(gaps.files.size(), 6u);
  ASSERT_EQ(gaps.notes.size(), 3u);
  EXPECT_NE(gaps.notes[2].find("a_016.tif .. a_017.tif (2 slices) are missing: converted without them"),
            std::string::npos)
      << gaps.notes[2];

  touch(dir + "/a_12.tiff");  // the same number as a_012.tif
  EXPECT_EQ(error_of([&] { scan_tiff_folder(dir, TiffFolderOptions{true}); }, &message), ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find("have the same slice number 12"), std::string::npos) << message;
  std::filesystem::remove(dir + "/a_12.tiff");
  touch(dir + "/b_013.tif");  // another numbering
  EXPECT_EQ(error_of([&] { scan_tiff_folder(dir, TiffFolderOptions{true}); }, &message), ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find(dir + "/b_013.tif does not follow the numbering of a_010.tif"), std::string::npos) << message;
}

TEST(TiffFolder, TheNumberThatChangesIsTheSlice) {
  const std::string dir = fresh_dir("changing");
  for (const char* name : {"part2_z9_v3.tif", "part2_z10_v3.tif", "part2_z11_v3.tif"}) touch(dir + "/" + name);
  const TiffFolder f = scan_tiff_folder(dir);
  ASSERT_EQ(f.files.size(), 3u);
  EXPECT_EQ(f.files[0], dir + "/part2_z9_v3.tif");
  EXPECT_EQ(f.files[2], dir + "/part2_z11_v3.tif");
  touch(dir + "/part2_z13_v3.tif");
  std::string message;
  EXPECT_EQ(error_of([&] { scan_tiff_folder(dir); }, &message), ivol::ErrorClass::Malformed);
  EXPECT_NE(message.find("part2_z13_v3.tif follows part2_z11_v3.tif: part2_z12_v3.tif is missing"), std::string::npos)
      << message;
}

TEST(Provenance, SourceProvenanceKeptAndUnknownVoxelSizeIsMarked) {
  DenseVolume v;
  v.provenance = R"({"created":"2026-01-01T00:00:00Z","command":"ivol recon ..."})";
  v.has_geometry = true;
  nlohmann::json p = provenance_after_conversion(v, "ivol convert a.ivol b.h5", "a.ivol", "ivol");
  EXPECT_EQ(p["derived_from"], nlohmann::json::parse(v.provenance));
  EXPECT_EQ(p["command"], "ivol convert a.ivol b.h5");
  EXPECT_EQ(p["sources"][0]["path"], "a.ivol");
  EXPECT_FALSE(p.contains("voxel_size_known"));
  v.has_geometry = false;
  v.provenance.clear();
  p = provenance_after_conversion(v, "ivol convert a.raw b.ivol", "a.raw", "raw");
  EXPECT_EQ(p["voxel_size_known"], false);
  EXPECT_EQ(p["sources"][0]["path"], "a.raw");
  EXPECT_TRUE(voxel_size_marked_unknown(p.dump()));
}
