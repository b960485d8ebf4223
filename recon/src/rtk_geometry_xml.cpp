#include "ivol/recon/rtk_geometry_xml.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <pugixml.hpp>
#include <stdexcept>
#include <string>
#include <vector>

namespace ivol::recon {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegree = kPi / 180.0;
constexpr const char* kRoot = "RTKThreeDCircularGeometry";

// One projection's parameters in RTK's terms (angles in degrees).
struct RtkParameters {
  double sid = 0.0;
  double sdd = 0.0;
  double gantry_angle = 0.0;
  double projection_offset_x = 0.0;
  double projection_offset_y = 0.0;
  double source_offset_x = 0.0;
  double source_offset_y = 0.0;
};

using Matrix34 = std::array<std::array<double, 4>, 3>;

// RTK's projection matrix for an untilted flat detector: rotation Ry(−θ) of
// the world, shift by the source offset, central projection with SDD and
// SID, shift by (source offset − projection offset). Maps RTK world points
// to physical coordinates on the projection image.
Matrix34 rtk_matrix(const RtkParameters& p) {
  const double c = std::cos(p.gantry_angle * kDegree);
  const double s = std::sin(p.gantry_angle * kDegree);
  // Rows of Ry(−θ): x_rot = c·x − s·z, y_rot = y, z_rot = s·x + c·z.
  const std::array<std::array<double, 3>, 3> r = {{{c, 0.0, -s}, {0.0, 1.0, 0.0}, {s, 0.0, c}}};
  const double tu = p.source_offset_x - p.projection_offset_x;
  const double tv = p.source_offset_y - p.projection_offset_y;
  // Homogeneous: h0 = −SDD·(x_rot − sx) + tu·h2, h1 = −SDD·(y_rot − sy) + tv·h2,
  // h2 = z_rot − SID.
  Matrix34 m{};
  for (int j = 0; j < 3; ++j) {
    m[2][j] = r[2][j];
    m[0][j] = -p.sdd * r[0][j] + tu * r[2][j];
    m[1][j] = -p.sdd * r[1][j] + tv * r[2][j];
  }
  m[2][3] = -p.sid;
  m[0][3] = p.sdd * p.source_offset_x - tu * p.sid;
  m[1][3] = p.sdd * p.source_offset_y - tv * p.sid;
  return m;
}

bool same_name(const char* a, const char* b) {
  for (; *a && *b; ++a, ++b)
    if (std::tolower(static_cast<unsigned char>(*a)) != std::tolower(static_cast<unsigned char>(*b))) return false;
  return *a == *b;
}

std::string trim(const std::string& text) {
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return {};
  return text.substr(first, text.find_last_not_of(" \t\r\n") - first + 1);
}

// Where an error is, for messages: "file: projection 3: element X".
struct Context {
  const std::string& path;
  long projection = -1;  // −1: outside any projection

  [[noreturn]] void fail(const std::string& element, const std::string& what) const {
    std::string where = path + ": ";
    if (projection >= 0) where += "projection " + std::to_string(projection) + ": ";
    if (!element.empty()) where += "element " + element + ": ";
    throw std::runtime_error(where + what);
  }
};

// The whole text of an element, strictly one number.
double parse_number(const pugi::xml_node& node, const Context& context) {
  if (node.find_child([](const pugi::xml_node& n) { return n.type() == pugi::node_element; }))
    context.fail(node.name(), "holds elements; expected a number");
  const std::string text = trim(node.child_value());
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    context.fail(node.name(), "\"" + text + "\" is not a finite number");
  return value;
}

Matrix34 parse_matrix(const pugi::xml_node& node, const Context& context) {
  const std::string text = node.child_value();
  std::vector<double> values;
  const char* p = text.data();
  const char* end = text.data() + text.size();
  while (true) {
    while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
    if (p == end) break;
    double value = 0.0;
    const auto [next, error] = std::from_chars(p, end, value);
    if (error != std::errc() || !std::isfinite(value))
      context.fail("Matrix", "value " + std::to_string(values.size()) + " is not a finite number");
    values.push_back(value);
    p = next;
  }
  if (values.size() != 12)
    context.fail("Matrix", "holds " + std::to_string(values.size()) + " numbers; a 3x4 matrix needs 12");
  Matrix34 m{};
  for (int i = 0; i < 12; ++i) m[i / 4][i % 4] = values[i];
  return m;
}

// True for an angle in degrees that is a whole number of turns (RTK stores
// angles modulo 360°, so a zero tilt may come back as 360).
bool is_zero_angle(double degrees) { return std::abs(std::remainder(degrees, 360.0)) <= 1e-9; }

// The running values, as RTK's reader keeps them: set by parameter elements
// wherever they appear, used when a projection ends.
struct State {
  std::optional<double> sid, sdd, gantry_angle;
  double projection_offset_x = 0.0, projection_offset_y = 0.0;
  double source_offset_x = 0.0, source_offset_y = 0.0;
  double in_plane_angle = 0.0, out_of_plane_angle = 0.0;
  double cylinder_radius = 0.0;
};

// Applies one parameter element; false when the name is not a parameter.
bool apply_parameter(const pugi::xml_node& node, State& state, const Context& context) {
  const char* name = node.name();
  auto is = [name](const char* candidate) { return same_name(name, candidate); };
  if (is("GantryAngle") || is("Angle")) {
    state.gantry_angle = parse_number(node, context);
  } else if (is("SourceToIsocenterDistance")) {
    state.sid = parse_number(node, context);
  } else if (is("SourceToDetectorDistance")) {
    state.sdd = parse_number(node, context);
  } else if (is("ProjectionOffsetX")) {
    state.projection_offset_x = parse_number(node, context);
  } else if (is("ProjectionOffsetY")) {
    state.projection_offset_y = parse_number(node, context);
  } else if (is("SourceOffsetX")) {
    state.source_offset_x = parse_number(node, context);
  } else if (is("SourceOffsetY")) {
    state.source_offset_y = parse_number(node, context);
  } else if (is("InPlaneAngle")) {
    state.in_plane_angle = parse_number(node, context);
  } else if (is("OutOfPlaneAngle")) {
    state.out_of_plane_angle = parse_number(node, context);
  } else if (is("RadiusCylindricalDetector")) {
    state.cylinder_radius = parse_number(node, context);
  } else if (is("CollimationUInf") || is("CollimationUSup") || is("CollimationVInf") || is("CollimationVSup")) {
    parse_number(node, context);  // checked, not used: collimation does not move rays
  } else {
    return false;
  }
  return true;
}

RtkParameters complete(const State& state, const Context& context) {
  if (!state.gantry_angle) context.fail("GantryAngle", "missing (neither in the projection nor before it)");
  if (!state.sid) context.fail("SourceToIsocenterDistance", "missing (neither in the projection nor before it)");
  if (!state.sdd) context.fail("SourceToDetectorDistance", "missing (neither in the projection nor before it)");
  if (*state.sdd == 0.0)
    context.fail("SourceToDetectorDistance", "0 means a parallel-beam projection, which is not supported");
  if (!is_zero_angle(state.in_plane_angle))
    context.fail("InPlaneAngle", std::to_string(state.in_plane_angle) +
                                     " degrees; only untilted detectors (InPlaneAngle 0) are supported");
  if (!is_zero_angle(state.out_of_plane_angle))
    context.fail("OutOfPlaneAngle", std::to_string(state.out_of_plane_angle) +
                                        " degrees; only untilted detectors (OutOfPlaneAngle 0) are supported");
  if (state.cylinder_radius != 0.0)
    context.fail("RadiusCylindricalDetector", "a curved detector is not supported (only flat panels)");
  RtkParameters p;
  p.sid = *state.sid;
  p.sdd = *state.sdd;
  p.gantry_angle = *state.gantry_angle;
  p.projection_offset_x = state.projection_offset_x;
  p.projection_offset_y = state.projection_offset_y;
  p.source_offset_x = state.source_offset_x;
  p.source_offset_y = state.source_offset_y;
  return p;
}

View to_view(const RtkParameters& p, const Detector& detector, double origin_u, double origin_v) {
  View v;
  v.angle = p.gantry_angle * kDegree;
  v.source_to_isocenter = p.sid;
  v.source_to_detector = p.sdd;
  v.source_offset_u = p.source_offset_x;
  v.source_offset_v = p.source_offset_y;
  v.detector_offset_u = p.projection_offset_x + origin_u + 0.5 * (detector.columns - 1) * detector.pitch_u;
  v.detector_offset_v = p.projection_offset_y + origin_v + 0.5 * (detector.rows - 1) * detector.pitch_v;
  return v;
}

RtkParameters to_rtk(const View& v, const Detector& detector, double origin_u, double origin_v) {
  RtkParameters p;
  p.gantry_angle = v.angle / kDegree;
  p.sid = v.source_to_isocenter;
  p.sdd = v.source_to_detector;
  p.source_offset_x = v.source_offset_u;
  p.source_offset_y = v.source_offset_v;
  p.projection_offset_x = v.detector_offset_u - origin_u - 0.5 * (detector.columns - 1) * detector.pitch_u;
  p.projection_offset_y = v.detector_offset_v - origin_v - 0.5 * (detector.rows - 1) * detector.pitch_v;
  return p;
}

// Projects a few points spread over the field of view both ways and compares.
void check_matrix(const Matrix34& m, const ScanGeometry& geometry, std::size_t view, double origin_u, double origin_v,
                  const Context& context) {
  const Detector& d = geometry.detector;
  const double r = 0.4 * geometry.views[view].source_to_isocenter;  // well inside the source circle
  const std::array<Vec3, 6> points = {{{0.0, 0.0, 0.0},
                                       {r, 0.0, 0.0},
                                       {0.0, r, 0.0},
                                       {0.0, 0.0, r},
                                       {0.5 * r, -0.3 * r, 0.7 * r},
                                       {-0.6 * r, 0.4 * r, -0.2 * r}}};
  const double extent_u = std::max({1.0, std::abs(origin_u), d.columns * d.pitch_u});
  const double extent_v = std::max({1.0, std::abs(origin_v), d.rows * d.pitch_v});
  for (const Vec3& point : points) {
    const std::array<double, 4> rtk = {point[0], point[2], -point[1], 1.0};  // x = X, y = Z, z = −Y
    std::array<double, 3> h{};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) h[i] += m[i][j] * rtk[j];
    if (h[2] == 0.0) context.fail("Matrix", "maps a point near the isocentre to infinity");
    const double u = h[0] / h[2];
    const double v = h[1] / h[2];
    const ScanGeometry::Projected ours = geometry.project(view, point);
    const double our_u = origin_u + ours.column * d.pitch_u;
    const double our_v = origin_v + ours.row * d.pitch_v;
    if (std::abs(our_u - u) > 1e-6 * std::max(extent_u, std::abs(u)) ||
        std::abs(our_v - v) > 1e-6 * std::max(extent_v, std::abs(v))) {
      char text[400];
      std::snprintf(text, sizeof text,
                    "the matrix projects world point (%g, %g, %g) mm (RTK frame) to (u, v) = (%.9g, %.9g) mm, "
                    "the projection's parameters to (%.9g, %.9g) mm: the file's matrix and parameters disagree",
                    rtk[0] + 0.0, rtk[1] + 0.0, rtk[2] + 0.0, u, v, our_u, our_v);
      context.fail("Matrix", text);
    }
  }
}

}  // namespace

ScanGeometry read_rtk_geometry_xml(const std::string& path, const Detector& detector, double projection_origin_u,
                                   double projection_origin_v) {
  Context context{path};
  pugi::xml_document document;
  const pugi::xml_parse_result parsed = document.load_file(path.c_str());
  if (parsed.status == pugi::status_file_not_found || parsed.status == pugi::status_io_error)
    context.fail("", std::string("cannot read the file: ") + parsed.description());
  if (!parsed)
    context.fail(
        "", std::string("not well-formed XML: ") + parsed.description() + " at byte " + std::to_string(parsed.offset));
  const pugi::xml_node root = document.document_element();
  if (!root || !same_name(root.name(), kRoot))
    context.fail(root ? root.name() : "", std::string("the root element must be <") + kRoot + ">");
  const pugi::xml_attribute version = root.attribute("version");
  if (!version) context.fail(kRoot, "has no version attribute");
  const std::string version_text = trim(version.value());
  if (version_text != "2" && version_text != "3")
    context.fail(kRoot, "version \"" + version_text + "\" is not supported (versions 2 and 3 are)");

  ScanGeometry geometry;
  geometry.detector = detector;
  std::vector<std::optional<Matrix34>> matrices;
  State state;
  for (const pugi::xml_node& node : root.children()) {
    if (node.type() != pugi::node_element) continue;
    if (!same_name(node.name(), "Projection")) {
      if (!apply_parameter(node, state, context)) context.fail(node.name(), "unknown element");
      continue;
    }
    Context here{path, static_cast<long>(geometry.views.size())};
    std::optional<Matrix34> matrix;
    for (const pugi::xml_node& child : node.children()) {
      if (child.type() != pugi::node_element) continue;
      if (same_name(child.name(), "Matrix"))
        matrix = parse_matrix(child, here);
      else if (!apply_parameter(child, state, here))
        here.fail(child.name(), "unknown element");
    }
    geometry.views.push_back(to_view(complete(state, here), detector, projection_origin_u, projection_origin_v));
    matrices.push_back(matrix);
  }
  if (geometry.views.empty()) context.fail("Projection", "the file holds no projections");
  try {
    geometry.validate();
  } catch (const std::invalid_argument& e) {
    context.fail("", e.what());
  }
  for (std::size_t i = 0; i < matrices.size(); ++i)
    if (matrices[i])
      check_matrix(*matrices[i], geometry, i, projection_origin_u, projection_origin_v,
                   Context{path, static_cast<long>(i)});
  return geometry;
}

namespace {

// Shortest text that reads back as the same double.
std::string number(double value) {
  if (value == 0.0) return "0";  // also −0
  char text[32];
  const auto [end, error] = std::to_chars(text, text + sizeof text, value);
  return error == std::errc() ? std::string(text, end) : std::string("nan");
}

std::string element(const char* name, double value) {
  return std::string("<") + name + ">" + number(value) + "</" + name + ">";
}

}  // namespace

void write_rtk_geometry_xml(const std::string& path, const ScanGeometry& geometry, double projection_origin_u,
                            double projection_origin_v) {
  geometry.validate();
  std::vector<RtkParameters> params;
  for (const View& v : geometry.views)
    params.push_back(to_rtk(v, geometry.detector, projection_origin_u, projection_origin_v));

  struct Field {
    const char* name;
    double RtkParameters::*member;
    bool omit_zero;  // RTK's writer leaves defaults (0) out
  };
  const std::array<Field, 6> fields = {{{"SourceToIsocenterDistance", &RtkParameters::sid, false},
                                        {"SourceToDetectorDistance", &RtkParameters::sdd, false},
                                        {"SourceOffsetX", &RtkParameters::source_offset_x, true},
                                        {"SourceOffsetY", &RtkParameters::source_offset_y, true},
                                        {"ProjectionOffsetX", &RtkParameters::projection_offset_x, true},
                                        {"ProjectionOffsetY", &RtkParameters::projection_offset_y, true}}};
  std::array<bool, fields.size()> global{};
  std::string text = "<?xml version=\"1.0\"?>\n<!DOCTYPE RTKGEOMETRY>\n<" + std::string(kRoot) + " version=\"3\">\n";
  for (std::size_t f = 0; f < fields.size(); ++f) {
    const double first = params[0].*fields[f].member;
    global[f] =
        std::all_of(params.begin(), params.end(), [&](const RtkParameters& p) { return p.*fields[f].member == first; });
    if (global[f] && !(fields[f].omit_zero && first == 0.0)) text += "  " + element(fields[f].name, first) + "\n";
  }
  for (const RtkParameters& p : params) {
    text += "  <Projection>\n    " + element("GantryAngle", p.gantry_angle) + "\n";
    for (std::size_t f = 0; f < fields.size(); ++f)
      if (!global[f]) text += "    " + element(fields[f].name, p.*fields[f].member) + "\n";
    text += "    <Matrix>\n";
    const Matrix34 m = rtk_matrix(p);
    for (const auto& row : m) {
      text += "      ";
      for (int j = 0; j < 4; ++j) {
        const std::string value = number(row[j]);
        text += std::string(value.size() < 24 ? 24 - value.size() : 0, ' ') + value + (j < 3 ? " " : "\n");
      }
    }
    text += "    </Matrix>\n  </Projection>\n";
  }
  text += "</" + std::string(kRoot) + ">\n";

  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(path + ": cannot create the file");
  out << text;
  out.close();
  if (!out) throw std::runtime_error(path + ": cannot write the file");
}

}  // namespace ivol::recon
