// Nikon .xtekct keys and angle files, and the geometry they map to, against
// a projection computed here in the frame public readers give these scans
// (docs/geometry.md, "Nikon XT scans"): the source at the origin, the beam
// along +y, the axis at (−ObjectOffsetX, SrcToObject), the detector's first
// pixel at the top right, the object turned by 180° − φ.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "ivol/error.hpp"
#include "xtekct.hpp"

namespace ivol::convert {
namespace {

const std::string kKeys =
    "[XTekCT]\r\nName=part\r\nProjections=3\r\nWhiteLevel=60000\r\nDetectorPixelsX=64\r\n"
    "DetectorPixelsY=48\r\nDetectorPixelSizeX=0.2\r\nDetectorPixelSizeY=0.25\r\nSrcToObject=150\r\n"
    "SrcToDetector=900\r\nInitialAngle=10\r\nAngularStep=120\r\nVoxelsX=8\r\nVoxelsY=9\r\nVoxelsZ=10\r\n"
    "VoxelSizeX=0.05\r\nVoxelSizeY=0.05\r\nVoxelSizeZ=0.05\r\n[Xrays]\r\nSrcToObject=1\r\nXraykV=160\r\n";

TEST(Xtekct, ReadsTheXtekctSectionOnly) {
  const XtekctKeys k = parse_xtekct(kKeys, "part.xtekct");
  EXPECT_EQ(k.name, "part");
  EXPECT_EQ(k.projections, 3u);
  EXPECT_EQ(k.src_to_object, 150.0);  // not [Xrays]'s
  EXPECT_EQ(k.pixel_size_y, 0.25);
  EXPECT_FALSE(k.object_offset_x.has_value());
  ASSERT_TRUE(k.has_grid);
  EXPECT_EQ(k.voxels[2], 10u);
}

TEST(Xtekct, NamesTheKeyThatIsWrong) {
  auto message = [](const std::string& text) {
    try {
      parse_xtekct(text, "s.xtekct");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  std::string missing = kKeys;
  missing.replace(missing.find("SrcToDetector=900"), 17, "Other=1");
  EXPECT_EQ(message(missing), "s.xtekct: key SrcToDetector is missing");
  std::string text = kKeys;
  text.replace(text.find("WhiteLevel=60000"), 16, "WhiteLevel=6e4x");
  EXPECT_EQ(message(text), "s.xtekct: key WhiteLevel is '6e4x', not a number");
  std::string behind = kKeys;
  behind.replace(behind.find("SrcToDetector=900"), 17, "SrcToDetector=100");
  EXPECT_NE(message(behind).find("SrcToDetector 100 is not beyond SrcToObject 150"), std::string::npos);
  EXPECT_NE(message("[Other]\nName=x\n").find("no [XTekCT] section"), std::string::npos);
}

TEST(Xtekct, AngleFilesSortedByIndex) {
  const std::vector<double> ct =
      parse_ctdata_angles("Nikon\nFrames 1\nProjection Angle Time\n2\t120.5\t1\n1\t0.25\t0\n3\t240\t2\n", "c", 3);
  EXPECT_EQ(ct, (std::vector<double>{0.25, 120.5, 240}));
  const std::vector<double> ang = parse_ang_angles("Projection\tAngle\n0003:\t240\n0002:\t120\n0001:\t0\n", "a", 3);
  EXPECT_EQ(ang, (std::vector<double>{0, 120, 240}));
  EXPECT_THROW(parse_ang_angles("h\n1: 0\n2: 1\n", "a", 3), Error);
  EXPECT_THROW(parse_ang_angles("h\n1: 0\n1: 1\n", "a", 2), Error);
  EXPECT_THROW(parse_ang_angles("h\n1: 0\n2: 1\n3: 2\n", "a", 2), Error);
}

// Column and row of a point (object frame, relative to the rotation axis)
// on the detector as stored in the TIFF, in the readers' frame.
struct Pixel {
  double column, row;
};
Pixel stored_pixel(const XtekctKeys& k, double offset, double phi_deg, const recon::Vec3& p) {
  const double alpha = (180.0 - phi_deg) * M_PI / 180.0;  // the object's turn, counter-clockwise about +z
  const double x = std::cos(alpha) * p[0] - std::sin(alpha) * p[1] - offset;
  const double y = std::sin(alpha) * p[0] + std::cos(alpha) * p[1] + k.src_to_object;
  const double scale = k.src_to_detector / y;
  // First pixel at the top right: columns run towards −x, rows downwards.
  return {0.5 * (k.pixels_x - 1) - x * scale / k.pixel_size_x, 0.5 * (k.pixels_y - 1) - p[2] * scale / k.pixel_size_y};
}

TEST(Xtekct, GeometryProjectsAsTheReadersFrameDoes) {
  for (const char* variant : {"ObjectOffsetX=0.7\n", "CentreOfRotationTop=4.2\nCentreOfRotationBottom=4.2\n", ""}) {
    const XtekctKeys k = parse_xtekct(kKeys.substr(0, kKeys.find("[Xrays]")) + variant, "s.xtekct");
    const double offset = std::string(variant).empty() ? 0.0 : 0.7;  // 4.2 · 150 / 900
    const std::vector<double> phi{10.0, 130.0, 250.0};
    const XtekctGeometry g = xtekct_geometry(k, phi, "s.xtekct");
    for (std::size_t v = 0; v < phi.size(); ++v)
      for (const recon::Vec3& p : {recon::Vec3{0, 0, 0}, recon::Vec3{3, -2, 1.5}, recon::Vec3{-4, 1, -2}}) {
        const auto ivol = g.geometry.project(v, p);
        const Pixel stored = stored_pixel(k, offset, phi[v], p);
        // ivol reads each image turned by 180°.
        EXPECT_NEAR(ivol.column, k.pixels_x - 1 - stored.column, 1e-9) << variant << " view " << v;
        EXPECT_NEAR(ivol.row, k.pixels_y - 1 - stored.row, 1e-9) << variant << " view " << v;
      }
  }
}

TEST(Xtekct, RefusesWhatTheGeometryCannotHold) {
  const std::string base = kKeys.substr(0, kKeys.find("[Xrays]"));
  const std::vector<double> phi{0, 120, 240};
  EXPECT_THROW(xtekct_geometry(parse_xtekct(base + "ObjectTilt=0.1\n", "s"), phi, "s"), Error);
  EXPECT_THROW(xtekct_geometry(parse_xtekct(base + "ObjectRoll=0.5\n", "s"), phi, "s"), Error);
  // A lean of less than a quarter pixel over the detector's height is read.
  EXPECT_NO_THROW(xtekct_geometry(parse_xtekct(base + "CentreOfRotationTop=0.04\n", "s"), phi, "s"));
  EXPECT_THROW(xtekct_geometry(parse_xtekct(base + "CentreOfRotationTop=0.06\n", "s"), phi, "s"), Error);
  EXPECT_THROW(xtekct_geometry(parse_xtekct(base + "DetectorOffsetY=1\n", "s"), phi, "s"), Error);
  EXPECT_THROW(xtekct_geometry(parse_xtekct(base, "s"), {0, 1}, "s"), Error);
}

}  // namespace
}  // namespace ivol::convert
