// RTK geometry files: a file laid out as RTK's XML writer lays it out, with the
// projection matrices computed here from RTK's definition
// (rtk::ThreeDCircularProjectionGeometry::AddProjectionInRadians: matrix =
// projection translation · magnification · source translation · rotation,
// rotation = ITK's Euler ZXY of (−out-of-plane, −gantry, −in-plane)), is read
// and our geometry must project world points where those matrices do.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"
#include "test_support.hpp"

namespace ivol::recon {
namespace {

constexpr double kPi = 3.14159265358979323846;

using M3 = std::array<std::array<double, 3>, 3>;
using M34 = std::array<std::array<double, 4>, 3>;

M3 multiply(const M3& a, const M3& b) {
  M3 c{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

// ITK Euler3DTransform with ComputeZYX off: R = Rz(z)·Rx(x)·Ry(y).
M3 euler_zxy(double x, double y, double z) {
  const M3 rx = {{{1, 0, 0}, {0, std::cos(x), -std::sin(x)}, {0, std::sin(x), std::cos(x)}}};
  const M3 ry = {{{std::cos(y), 0, std::sin(y)}, {0, 1, 0}, {-std::sin(y), 0, std::cos(y)}}};
  const M3 rz = {{{std::cos(z), -std::sin(z), 0}, {std::sin(z), std::cos(z), 0}, {0, 0, 1}}};
  return multiply(rz, multiply(rx, ry));
}

struct RtkProjection {
  double sid, sdd, gantry_deg, proj_x, proj_y, src_x, src_y;
  double out_of_plane_deg = 0.0, in_plane_deg = 0.0;
};

// RTK's matrix, composed step by step as RTK documents it.
M34 rtk_matrix(const RtkProjection& p) {
  const double d = kPi / 180.0;
  const M3 r = euler_zxy(-p.out_of_plane_deg * d, -p.gantry_deg * d, -p.in_plane_deg * d);
  // 4x4 rotation, then source translation (−sx, −sy, 0).
  double rs[4][4] = {};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rs[i][j] = r[i][j];
  rs[3][3] = 1.0;
  rs[0][3] = -p.src_x;
  rs[1][3] = -p.src_y;
  // Magnification with (−sdd, −sid): [[−sdd,0,0,0],[0,−sdd,0,0],[0,0,1,−sid]].
  const double mag[3][4] = {{-p.sdd, 0, 0, 0}, {0, -p.sdd, 0, 0}, {0, 0, 1, -p.sid}};
  double ms[3][4] = {};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) ms[i][j] += mag[i][k] * rs[k][j];
  // Projection translation (sx − px, sy − py).
  const double t[3][3] = {{1, 0, p.src_x - p.proj_x}, {0, 1, p.src_y - p.proj_y}, {0, 0, 1}};
  M34 m{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 3; ++k) m[i][j] += t[i][k] * ms[k][j];
  return m;
}

// A file as RTK's ThreeDCircularProjectionGeometryXMLFileWriter writes it:
// 15 significant digits, matrix entries in fields of 19.
class RtkFile {
 public:
  RtkFile() {
    out_.precision(15);
    out_ << "<?xml version=\"1.0\"?>\n<!DOCTYPE RTKGEOMETRY>\n<RTKThreeDCircularGeometry version=\"3\">\n";
  }
  void global(const std::string& name, double value) { out_ << "  <" << name << ">" << value << "</" << name << ">\n"; }
  // `local` are the per-projection elements after GantryAngle.
  void projection(const RtkProjection& p, const std::vector<std::pair<std::string, double>>& local,
                  const M34* matrix_override = nullptr) {
    out_ << "  <Projection>\n    <GantryAngle>" << p.gantry_deg << "</GantryAngle>\n";
    for (const auto& [name, value] : local) out_ << "    <" << name << ">" << value << "</" << name << ">\n";
    out_ << "    <Matrix>\n";
    const M34 m = matrix_override ? *matrix_override : rtk_matrix(p);
    for (const auto& row : m) {
      out_ << "      ";
      for (int k = 0; k < 4; ++k) out_ << std::setw(19) << row[k] << (k < 3 ? " " : "\n");
    }
    out_ << "    </Matrix>\n  </Projection>\n";
  }
  std::string save(const std::string& name) {
    const std::string path = ivol::test::temp_path(name);
    std::ofstream(path) << out_.str() << "</RTKThreeDCircularGeometry>\n";
    return path;
  }

 private:
  std::ostringstream out_;
};

const Detector kDetector{64, 48, 0.8, 0.6};
// A projection image origin that is not centred: (columns − 1)/2 · pitch is
// 25.2 and (rows − 1)/2 · pitch is 14.1.
constexpr double kOriginU = -25.2 + 1.3;
constexpr double kOriginV = -14.1 - 0.7;

// Global SID, SDD, SourceOffsetY, ProjectionOffsetY; per projection
// GantryAngle, SourceOffsetX, ProjectionOffsetX.
std::vector<RtkProjection> sample_projections() {
  std::vector<RtkProjection> list;
  const double angles[] = {0.0, 37.5, 123.25, 270.0, 359.0};
  for (int i = 0; i < 5; ++i) list.push_back({800.0, 1200.0, angles[i], -3.5 + 1.25 * i, 2.5, 0.75 * i - 1.0, 3.0});
  return list;
}

std::string write_sample(const std::string& name, int corrupt_matrix_of = -1) {
  RtkFile file;
  file.global("SourceToIsocenterDistance", 800.0);
  file.global("SourceToDetectorDistance", 1200.0);
  file.global("SourceOffsetY", 3.0);
  file.global("ProjectionOffsetY", 2.5);
  int i = 0;
  for (const RtkProjection& p : sample_projections()) {
    M34 wrong{};
    if (i == corrupt_matrix_of) {
      // The matrix of the mirrored rotation: what a sign error in the
      // gantry angle convention would produce.
      RtkProjection mirrored = p;
      mirrored.gantry_deg = -p.gantry_deg;
      wrong = rtk_matrix(mirrored);
    }
    file.projection(p, {{"SourceOffsetX", p.src_x}, {"ProjectionOffsetX", p.proj_x}},
                    i == corrupt_matrix_of ? &wrong : nullptr);
    ++i;
  }
  return file.save(name);
}

// Where RTK's matrix puts a world point given in our frame: RTK (x, y, z) =
// (X, Z, −Y); column = (u − origin_u) / pitch_u.
std::array<double, 2> rtk_pixel(const M34& m, const Vec3& p) {
  const double w[4] = {p[0], p[2], -p[1], 1.0};
  double h[3] = {};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) h[i] += m[i][j] * w[j];
  return {(h[0] / h[2] - kOriginU) / kDetector.pitch_u, (h[1] / h[2] - kOriginV) / kDetector.pitch_v};
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(RtkGeometryXml, ReadsRtkLayoutAndProjectsAsTheMatrices) {
  const std::string path = write_sample("sample.xml");
  const ScanGeometry g = read_rtk_geometry_xml(path, kDetector, kOriginU, kOriginV);
  const auto projections = sample_projections();
  ASSERT_EQ(g.view_count(), projections.size());
  EXPECT_EQ(g.detector.columns, 64);
  for (std::size_t i = 0; i < projections.size(); ++i) {
    const RtkProjection& p = projections[i];
    const View& v = g.views[i];
    EXPECT_NEAR(v.angle, p.gantry_deg * kPi / 180.0, 1e-12);
    EXPECT_EQ(v.source_to_isocenter, 800.0);
    EXPECT_EQ(v.source_to_detector, 1200.0);
    EXPECT_EQ(v.source_offset_u, p.src_x);
    EXPECT_EQ(v.source_offset_v, 3.0);
    EXPECT_NEAR(v.detector_offset_u, p.proj_x + kOriginU + 31.5 * 0.8, 1e-12);
    EXPECT_NEAR(v.detector_offset_v, 2.5 + kOriginV + 23.5 * 0.6, 1e-12);

    const M34 m = rtk_matrix(p);
    const Vec3 points[] = {{0, 0, 0}, {40, -25, 12}, {-60, 10, -30}, {5, 70, 45}, {-100, -100, 20}};
    for (const Vec3& point : points) {
      const auto expected = rtk_pixel(m, point);
      const auto ours = g.project(i, point);
      EXPECT_NEAR(ours.column, expected[0], 1e-9) << "view " << i;
      EXPECT_NEAR(ours.row, expected[1], 1e-9) << "view " << i;
    }
    // The source: RTK puts it at R⁻¹ (sx, sy, SID) = Rᵀ (sx, sy, SID).
    const M3 r = euler_zxy(0.0, -p.gantry_deg * kPi / 180.0, 0.0);
    const double local[3] = {p.src_x, p.src_y, p.sid};
    double world[3] = {};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) world[a] += r[b][a] * local[b];
    const Vec3 s = g.source_position(i);
    EXPECT_NEAR(s[0], world[0], 1e-9);
    EXPECT_NEAR(s[1], -world[2], 1e-9);
    EXPECT_NEAR(s[2], world[1], 1e-9);
  }
}

TEST(RtkGeometryXml, MatrixThatDisagreesWithTheParametersIsRefused) {
  const std::string path = write_sample("wrong_matrix.xml", 2);
  try {
    read_rtk_geometry_xml(path, kDetector, kOriginU, kOriginV);
    FAIL() << "a mirrored matrix was accepted";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path), std::string::npos) << message;
    EXPECT_NE(message.find("projection 2"), std::string::npos) << message;
    EXPECT_NE(message.find("Matrix"), std::string::npos) << message;
  }
}

TEST(RtkGeometryXml, VersionTwoOldAngleNameAndCarriedOverValues) {
  // As RTK's SAX reader: a value set in a projection stays for the next ones.
  const std::string path = ivol::test::temp_path("v2.xml");
  std::ofstream(path) << "<?xml version=\"1.0\"?>\n<!DOCTYPE RTKGEOMETRY>\n"
                         "<RTKThreeDCircularGeometry version=\"2\">\n"
                         "  <SourceToIsocenterDistance>500</SourceToIsocenterDistance>\n"
                         "  <SourceToDetectorDistance>900</SourceToDetectorDistance>\n"
                         "  <Projection><Angle>10</Angle></Projection>\n"
                         "  <Projection><GantryAngle>20</GantryAngle><SourceOffsetX>4</SourceOffsetX></Projection>\n"
                         "  <Projection><GantryAngle>30</GantryAngle></Projection>\n"
                         "  <Projection><gantryangle>40</gantryangle><SourceOffsetX>0</SourceOffsetX>"
                         "<SourceToIsocenterDistance>450</SourceToIsocenterDistance></Projection>\n"
                         "</RTKThreeDCircularGeometry>\n";
  const ScanGeometry g = read_rtk_geometry_xml(path, kDetector, -25.2, -14.1);
  ASSERT_EQ(g.view_count(), 4u);
  EXPECT_NEAR(g.views[0].angle, 10 * kPi / 180, 1e-15);
  EXPECT_EQ(g.views[0].source_offset_u, 0.0);
  EXPECT_EQ(g.views[1].source_offset_u, 4.0);
  EXPECT_EQ(g.views[2].source_offset_u, 4.0);
  EXPECT_EQ(g.views[3].source_offset_u, 0.0);
  EXPECT_EQ(g.views[2].source_to_isocenter, 500.0);
  EXPECT_EQ(g.views[3].source_to_isocenter, 450.0);
  EXPECT_NEAR(g.views[0].detector_offset_u, 0.0, 1e-12);  // centred origin: no offset
  EXPECT_NEAR(g.views[0].detector_offset_v, 0.0, 1e-12);
}

TEST(RtkGeometryXml, WriteThenReadRoundTrips) {
  ScanGeometry g = circular_scan(kDetector, 7, 650.0, 1100.0, 2 * kPi, 0.3, 1.75, -0.5);
  for (std::size_t i = 0; i < g.views.size(); ++i) {
    g.views[i].source_offset_u = 0.5 * static_cast<double>(i);
    g.views[i].source_offset_v = -1.5;
    g.views[i].source_to_detector = 1100.0 + static_cast<double>(i);
  }
  const std::string path = ivol::test::temp_path("roundtrip.xml");
  write_rtk_geometry_xml(path, g, kOriginU, kOriginV);
  const ScanGeometry back = read_rtk_geometry_xml(path, kDetector, kOriginU, kOriginV);
  ASSERT_EQ(back.view_count(), g.view_count());
  for (std::size_t i = 0; i < g.views.size(); ++i) {
    const View& a = g.views[i];
    const View& b = back.views[i];
    EXPECT_NEAR(b.angle, a.angle, 1e-13);
    EXPECT_EQ(b.source_to_isocenter, a.source_to_isocenter);
    EXPECT_EQ(b.source_to_detector, a.source_to_detector);
    EXPECT_NEAR(b.detector_offset_u, a.detector_offset_u, 1e-12);
    EXPECT_NEAR(b.detector_offset_v, a.detector_offset_v, 1e-12);
    EXPECT_EQ(b.source_offset_u, a.source_offset_u);
    EXPECT_EQ(b.source_offset_v, a.source_offset_v);
  }
  // RTK's layout: constant parameters once before the projections, varying
  // ones in every projection, zero tilts left out.
  const std::string text = read_text(path);
  EXPECT_EQ(text.rfind("<?xml version=\"1.0\"?>\n<!DOCTYPE RTKGEOMETRY>\n<RTKThreeDCircularGeometry version=\"3\">", 0),
            0u);
  const auto first_projection = text.find("<Projection>");
  EXPECT_LT(text.find("<SourceToIsocenterDistance>650</SourceToIsocenterDistance>"), first_projection);
  EXPECT_LT(text.find("<SourceOffsetY>-1.5</SourceOffsetY>"), first_projection);
  EXPECT_GT(text.find("<SourceToDetectorDistance>1106</SourceToDetectorDistance>"), first_projection);
  EXPECT_EQ(text.find("InPlaneAngle"), std::string::npos);
  EXPECT_LT(text.find("<ProjectionOffsetX>"), first_projection);  // one detector offset for all views
  // The written matrices are RTK's (computed here) for the written parameters.
  std::size_t at = 0;
  for (std::size_t i = 0; i < g.views.size(); ++i) {
    at = text.find("<Matrix>", at);
    ASSERT_NE(at, std::string::npos);
    std::istringstream values(text.substr(at + 8));
    M34 m{};
    for (auto& row : m)
      for (double& x : row) values >> x;
    const View& v = g.views[i];
    const RtkProjection p{v.source_to_isocenter,
                          v.source_to_detector,
                          v.angle * 180.0 / kPi,
                          v.detector_offset_u - kOriginU - 31.5 * 0.8,
                          v.detector_offset_v - kOriginV - 23.5 * 0.6,
                          v.source_offset_u,
                          v.source_offset_v};
    const M34 expected = rtk_matrix(p);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(m[r][c], expected[r][c], 1e-9 * (1 + std::abs(expected[r][c])));
    ++at;
  }
}

// Expects a runtime_error whose message names the file and every `part`.
void expect_refused(const std::string& xml, const std::string& name, const std::vector<std::string>& parts) {
  const std::string path = ivol::test::temp_path(name);
  std::ofstream(path) << xml;
  try {
    read_rtk_geometry_xml(path, kDetector, -25.2, -14.1);
    ADD_FAILURE() << name << " was accepted";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path), std::string::npos) << message;
    for (const auto& part : parts)
      EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' in " << message;
  }
}

const std::string kHead = "<?xml version=\"1.0\"?>\n<RTKThreeDCircularGeometry version=\"3\">\n";
const std::string kDistances =
    "<SourceToIsocenterDistance>500</SourceToIsocenterDistance>"
    "<SourceToDetectorDistance>900</SourceToDetectorDistance>\n";
const std::string kTail = "</RTKThreeDCircularGeometry>\n";

TEST(RtkGeometryXml, RefusesWhatItCannotRepresent) {
  expect_refused(kHead + kDistances + "<InPlaneAngle>5</InPlaneAngle><Projection><GantryAngle>0</GantryAngle>" +
                     "</Projection>" + kTail,
                 "in_plane.xml", {"projection 0", "InPlaneAngle"});
  expect_refused(kHead + kDistances + "<Projection><GantryAngle>0</GantryAngle></Projection>" +
                     "<Projection><GantryAngle>1</GantryAngle></Projection>" +
                     "<Projection><GantryAngle>2</GantryAngle><OutOfPlaneAngle>-3</OutOfPlaneAngle></Projection>" +
                     kTail,
                 "out_of_plane.xml", {"projection 2", "OutOfPlaneAngle"});
  expect_refused(kHead + "<SourceToIsocenterDistance>1000</SourceToIsocenterDistance>" +
                     "<SourceToDetectorDistance>0</SourceToDetectorDistance>" +
                     "<Projection><GantryAngle>0</GantryAngle></Projection>" + kTail,
                 "parallel.xml", {"projection 0", "SourceToDetectorDistance", "parallel"});
  expect_refused(kHead + kDistances + "<RadiusCylindricalDetector>300</RadiusCylindricalDetector>" +
                     "<Projection><GantryAngle>0</GantryAngle></Projection>" + kTail,
                 "curved.xml", {"RadiusCylindricalDetector"});
}

TEST(RtkGeometryXml, RefusesBrokenFiles) {
  expect_refused(kHead + kDistances + "<Projection><GantryAngle>0</GantryAngle></Projection" + kTail, "malformed.xml",
                 {"not well-formed XML"});
  expect_refused(kHead + "<SourceToDetectorDistance>900</SourceToDetectorDistance>" +
                     "<Projection><GantryAngle>0</GantryAngle></Projection>" + kTail,
                 "no_sid.xml", {"projection 0", "SourceToIsocenterDistance", "missing"});
  expect_refused(kHead + kDistances + "<Projection><SourceOffsetX>1</SourceOffsetX></Projection>" + kTail,
                 "no_angle.xml", {"projection 0", "GantryAngle", "missing"});
  expect_refused(kHead + kDistances + "<Projection><GantryAngle>1O</GantryAngle></Projection>" + kTail,
                 "not_number.xml", {"projection 0", "GantryAngle", "1O"});
  expect_refused(
      kHead + kDistances + "<Projection><GantryAngle>0</GantryAngle><Matrix>1 2 3</Matrix></Projection>" + kTail,
      "short_matrix.xml", {"projection 0", "Matrix", "12"});
  expect_refused(kHead + kDistances + "<Projection><GantryAngle>0</GantryAngle><Tilt>1</Tilt></Projection>" + kTail,
                 "unknown.xml", {"projection 0", "Tilt", "unknown"});
  expect_refused("<?xml version=\"1.0\"?>\n<RTKThreeDCircularGeometry version=\"1\">" + kDistances +
                     "<Projection><GantryAngle>0</GantryAngle></Projection>" + kTail,
                 "version1.xml", {"RTKThreeDCircularGeometry", "version"});
  expect_refused("<?xml version=\"1.0\"?>\n<Geometry version=\"3\"/>\n", "wrong_root.xml", {"Geometry", "root"});
  expect_refused(kHead + kDistances + kTail, "empty.xml", {"no projections"});
  // SDD ≤ SID: our validate() refuses, and the message names the file.
  expect_refused(kHead + "<SourceToIsocenterDistance>900</SourceToIsocenterDistance>" +
                     "<SourceToDetectorDistance>500</SourceToDetectorDistance>" +
                     "<Projection><GantryAngle>0</GantryAngle></Projection>" + kTail,
                 "sdd_short.xml", {"view 0", "source-to-detector"});
  try {
    read_rtk_geometry_xml(ivol::test::temp_path("absent.xml"), kDetector, 0, 0);
    ADD_FAILURE() << "a missing file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("absent.xml"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace ivol::recon
