// The named phantoms. Each industrial part is built in its own frame, in
// units of the field-of-view radius R, then turned and moved into the world.
// Densities are rough linear attenuation coefficients near 80 keV, in 1/mm.
#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "ivol/recon/phantom.hpp"

namespace ivol::recon {
namespace {

constexpr double kPi = 3.14159265358979323846;

constexpr double kWood = 0.009;
constexpr double kGraphite = 0.035;
constexpr double kPlastic = 0.02;  // cups, pen bodies
constexpr double kConnectorPlastic = 0.025;
constexpr double kGlassEpoxy = 0.035;     // FR4 circuit boards
constexpr double kMouldCompound = 0.035;  // chip packages
constexpr double kSilicon = 0.045;
constexpr double kCeramic = 0.07;  // surface-mount bodies
constexpr double kCopper = 0.4;
constexpr double kBrass = 0.35;
constexpr double kSteel = 0.4;
constexpr double kSolder = 1.0;
constexpr double kCarbonFibre = 0.027;
constexpr double kAluminium = 0.045;
constexpr double kTitanium = 0.12;

double radians(double degrees) { return degrees * kPi / 180.0; }
Rotation about_x(double degrees) { return rotation_about_axis({1.0, 0.0, 0.0}, radians(degrees)); }
Rotation about_y(double degrees) { return rotation_about_axis({0.0, 1.0, 0.0}, radians(degrees)); }
Rotation about_z(double degrees) { return rotation_about_axis({0.0, 0.0, 1.0}, radians(degrees)); }

Rotation multiply(const Rotation& a, const Rotation& b) {
  Rotation m{};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 3; ++k) m[r * 3 + c] += a[r * 3 + k] * b[k * 3 + c];
  return m;
}

Vec3 rotate(const Rotation& m, const Vec3& v) {
  return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
          m[6] * v[0] + m[7] * v[1] + m[8] * v[2]};
}

Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 scaled(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }

Shape make(ShapeKind kind, const Vec3& centre, const Vec3& half_size, double density,
           const Rotation& rotation = kIdentityRotation) {
  return Shape{kind, centre, half_size, rotation, density};
}

// A rotation turning local z onto direction d (about z × d).
Rotation z_onto(const Vec3& d) {
  const Vec3 axis{-d[1], d[0], 0.0};
  const double sine = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1]);
  const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (sine > 1e-12 * length) return rotation_about_axis(axis, std::atan2(sine, d[2]));
  return d[2] < 0.0 ? about_x(180.0) : kIdentityRotation;
}

// A round cylinder of `radius` from point `a` to point `b`.
Shape rod(const Vec3& a, const Vec3& b, double radius, double density) {
  const Vec3 d{b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  return make(ShapeKind::Cylinder, scaled(add(a, b), 0.5), {radius, radius, 0.5 * length}, density, z_onto(d));
}

// Moves shapes built in a part's frame into the world: p → rotation · p + offset.
void place(std::vector<Shape>& shapes, std::size_t first, const Rotation& rotation, const Vec3& offset) {
  for (std::size_t n = first; n < shapes.size(); ++n) {
    shapes[n].centre = add(rotate(rotation, shapes[n].centre), offset);
    shapes[n].rotation = multiply(rotation, shapes[n].rotation);
  }
}

// A surface-mount part lying on z = base: a body between two metal end caps,
// `length` long along x before turning by `degrees` about z.
void smd_part(std::vector<Shape>& out, double x, double y, double base, double length, double width, double height,
              double degrees) {
  const std::size_t first = out.size();
  const double cap = 0.2 * length;
  const double body = 0.5 * length - cap;
  out.push_back(make(ShapeKind::Box, {0.0, 0.0, 0.0}, {body, 0.5 * width, 0.5 * height}, kCeramic));
  for (double side : {-1.0, 1.0})
    out.push_back(
        make(ShapeKind::Box, {side * (body + 0.5 * cap), 0.0, 0.0}, {0.5 * cap, 0.5 * width, 0.5 * height}, kSteel));
  place(out, first, about_z(degrees), {x, y, base + 0.5 * height});
}

// A package on a grid of solder balls on z = base: balls of `ball` radius at
// `pitch`, nx × ny of them, the package body `half` above them.
void ball_grid_package(std::vector<Shape>& out, double x, double y, double base, const Vec3& half, int nx, int ny,
                       double pitch, double ball) {
  for (int a = 0; a < nx; ++a)
    for (int b = 0; b < ny; ++b)
      out.push_back(make(ShapeKind::Ellipsoid,
                         {x + (a - 0.5 * (nx - 1)) * pitch, y + (b - 0.5 * (ny - 1)) * pitch, base + ball},
                         {ball, ball, ball}, kSolder));
  const double z = base + 2.0 * ball + half[2];
  out.push_back(make(ShapeKind::Box, {x, y, z}, half, kMouldCompound));
  // The die replaces mould compound in the middle of the package.
  out.push_back(
      make(ShapeKind::Box, {x, y, z}, {0.45 * half[0], 0.45 * half[1], 0.25 * half[2]}, kSilicon - kMouldCompound));
}

void check_radius(double fov_radius) {
  if (!(fov_radius > 0.0) || !std::isfinite(fov_radius))
    throw std::invalid_argument("phantom: the field-of-view radius must be positive and finite");
}

}  // namespace

Phantom pencil_holder(double R) {
  check_radius(R);
  Phantom p;
  auto& s = p.shapes;
  // The cup: 1.2 R tall, 0.04 R wall, 0.06 R base, open at the top.
  const double top = 0.35 * R, bottom = -0.85 * R, floor = bottom + 0.06 * R;
  const double outer = 0.55 * R, inner = 0.51 * R;
  s.push_back(
      make(ShapeKind::Cylinder, {0.0, 0.0, 0.5 * (top + bottom)}, {outer, outer, 0.5 * (top - bottom)}, kPlastic));
  s.push_back(
      make(ShapeKind::Cylinder, {0.0, 0.0, 0.5 * (top + floor)}, {inner, inner, 0.5 * (top - floor)}, -kPlastic));
  // A foot ring round the outside near the base.
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, bottom + 0.05 * R},
                   {outer + 0.015 * R, outer + 0.015 * R, 0.015 * R}, kPlastic));
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, bottom + 0.05 * R}, {outer, outer, 0.015 * R}, -kPlastic));
  // Three pencils leaning outwards: wood round a graphite core.
  for (double degrees : {20.0, 140.0, 260.0}) {
    const double c = std::cos(radians(degrees)), sn = std::sin(radians(degrees));
    const double length = 1.45 * R, spread = 0.31 * R;
    const Vec3 a{0.12 * R * c, 0.12 * R * sn, floor + 0.05 * R};
    const Vec3 b{a[0] + spread * c, a[1] + spread * sn, a[2] + std::sqrt(length * length - spread * spread)};
    s.push_back(rod(a, b, 0.035 * R, kWood));
    s.push_back(rod(a, b, 0.01 * R, kGraphite - kWood));
  }
  // A pen near the axis, 3° off vertical: a hollow body holding an ink
  // refill, a brass tip ending in a steel ball.
  const Vec3 axis{std::sin(radians(3.0)) * std::cos(radians(200.0)), std::sin(radians(3.0)) * std::sin(radians(200.0)),
                  std::cos(radians(3.0))};
  const Vec3 ball{0.0, 0.0, floor + 0.015 * R};
  auto along = [&](double t) { return add(ball, scaled(axis, t * R)); };
  s.push_back(rod(along(0.03), along(1.15), 0.025 * R, kPlastic));
  s.push_back(rod(along(0.03), along(1.15), 0.015 * R, -kPlastic));
  s.push_back(rod(along(0.05), along(1.1), 0.006 * R, kPlastic));
  s.push_back(make(ShapeKind::Ellipsoid, along(0.022), {0.01 * R, 0.01 * R, 0.018 * R}, kBrass, z_onto(axis)));
  s.push_back(make(ShapeKind::Ellipsoid, ball, {0.004 * R, 0.004 * R, 0.004 * R}, kSteel));
  // A steel paper clip lying on the base: two wires joined at one end.
  const std::size_t clip = s.size();
  const double wire = 0.004 * R;
  for (double side : {-1.0, 1.0})
    s.push_back(make(ShapeKind::Box, {0.0, side * 0.02 * R, 0.0}, {0.1 * R, wire, wire}, kSteel));
  s.push_back(make(ShapeKind::Box, {0.1 * R + wire, 0.0, 0.0}, {wire, 0.02 * R + wire, wire}, kSteel));
  place(s, clip, about_z(35.0), {0.3 * R * std::cos(radians(80.0)), 0.3 * R * std::sin(radians(80.0)), floor + wire});
  return p;
}

Phantom connector_board(double R) {
  check_radius(R);
  Phantom p;
  auto& s = p.shapes;
  // Built lying in the xy plane, parts on +z; then stood up.
  const double t = 0.016 * R;  // half the board's thickness
  s.push_back(make(ShapeKind::Box, {0.0, 0.0, 0.0}, {0.7 * R, 0.4 * R, t}, kGlassEpoxy));
  for (double x : {-0.62 * R, 0.62 * R})
    for (double y : {-0.32 * R, 0.32 * R})
      s.push_back(make(ShapeKind::Cylinder, {x, y, 0.0}, {0.03 * R, 0.03 * R, t}, -kGlassEpoxy));
  // A two-row socket: a plastic housing with 2 × 12 pins through the board.
  const double pin = 0.008 * R;
  s.push_back(
      make(ShapeKind::Box, {-0.15 * R, 0.2 * R, t + 0.07 * R}, {0.32 * R, 0.05 * R, 0.07 * R}, kConnectorPlastic));
  for (int k = 0; k < 12; ++k)
    for (double y : {0.18 * R, 0.22 * R}) {
      const double x = -0.15 * R + (k - 5.5) * 0.05 * R;
      s.push_back(rod({x, y, -0.07 * R}, {x, y, t + 0.12 * R}, pin, kBrass));
    }
  // A right-angle header: pins come up through the board and turn towards −y.
  s.push_back(
      make(ShapeKind::Box, {0.4 * R, -0.2 * R, t + 0.05 * R}, {0.15 * R, 0.04 * R, 0.05 * R}, kConnectorPlastic));
  for (int k = 0; k < 6; ++k) {
    const double x = 0.4 * R + (k - 2.5) * 0.05 * R, z = t + 0.05 * R;
    s.push_back(rod({x, -0.2 * R, -0.06 * R}, {x, -0.2 * R, z + pin}, pin, kBrass));
    s.push_back(rod({x, -0.2 * R - pin, z}, {x, -0.34 * R, z}, pin, kBrass));
  }
  // Surface-mount resistors and copper traces on the back.
  const double smd[][3] = {
      {0.1, -0.05, 0.0}, {0.2, -0.05, 0.0}, {0.3, 0.05, 90.0}, {-0.4, -0.2, 90.0}, {-0.25, -0.25, 0.0}};
  for (const auto& m : smd) smd_part(s, m[0] * R, m[1] * R, t, 0.08 * R, 0.03 * R, 0.02 * R, m[2]);
  for (int k = 0; k < 4; ++k)
    s.push_back(make(ShapeKind::Box, {-0.15 * R, (-0.3 + 0.05 * k) * R, -t - 0.0008 * R},
                     {0.4 * R, 0.004 * R, 0.0008 * R}, kCopper));
  place(s, 0, multiply(about_z(7.0), about_x(94.0)), {0.0, 0.04 * R, 0.0});
  return p;
}

Phantom computer_board(double R) {
  check_radius(R);
  Phantom p;
  auto& s = p.shapes;
  const double t = 0.012 * R;  // half the board's thickness
  s.push_back(make(ShapeKind::Box, {0.0, 0.0, 0.0}, {0.72 * R, 0.46 * R, t}, kGlassEpoxy));
  // An inner copper plane, replacing glass-epoxy.
  const double plane = 0.0008 * R;
  s.push_back(make(ShapeKind::Box, {0.0, 0.0, 0.0}, {0.7 * R, 0.44 * R, plane}, kCopper - kGlassEpoxy));
  for (double x : {-0.64 * R, 0.64 * R})
    for (double y : {-0.38 * R, 0.38 * R}) {
      s.push_back(make(ShapeKind::Cylinder, {x, y, 0.0}, {0.025 * R, 0.025 * R, t}, -kGlassEpoxy));
      s.push_back(make(ShapeKind::Cylinder, {x, y, 0.0}, {0.025 * R, 0.025 * R, plane}, -(kCopper - kGlassEpoxy)));
    }
  // Processor and memory on solder balls.
  ball_grid_package(s, -0.15 * R, 0.05 * R, t, {0.13 * R, 0.13 * R, 0.012 * R}, 8, 8, 0.03 * R, 0.007 * R);
  ball_grid_package(s, 0.2 * R, 0.12 * R, t, {0.1 * R, 0.07 * R, 0.01 * R}, 6, 4, 0.03 * R, 0.006 * R);
  // A 2 × 12 pin header along one edge.
  s.push_back(
      make(ShapeKind::Box, {-0.05 * R, 0.4 * R, t + 0.025 * R}, {0.3 * R, 0.025 * R, 0.025 * R}, kConnectorPlastic));
  for (int k = 0; k < 12; ++k)
    for (double y : {0.3875 * R, 0.4125 * R}) {
      const double x = -0.05 * R + (k - 5.5) * 0.05 * R;
      s.push_back(rod({x, y, -t - 0.02 * R}, {x, y, t + 0.1 * R}, 0.005 * R, kBrass));
    }
  // Two USB-like sockets at the edge: steel shells open along x with a
  // plastic tongue inside.
  const double wall = 0.004 * R;
  for (double y : {-0.25 * R, -0.05 * R}) {
    const Vec3 c{0.62 * R, y, t + 0.08 * R};
    s.push_back(make(ShapeKind::Box, c, {0.09 * R, 0.07 * R, 0.08 * R}, kSteel));
    s.push_back(make(ShapeKind::Box, c, {0.09 * R, 0.07 * R - wall, 0.08 * R - wall}, -kSteel));
    s.push_back(make(ShapeKind::Box, c, {0.07 * R, 0.04 * R, 0.008 * R}, kConnectorPlastic));
  }
  // Small capacitors in the free areas.
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b)
      smd_part(s, (-0.62 + 0.08 * a) * R, (-0.3 + 0.17 * b) * R, t, 0.038 * R, 0.016 * R, 0.016 * R,
               (a + b) % 2 * 90.0);
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 3; ++b)
      smd_part(s, (0.05 + 0.1 * a) * R, (-0.38 + 0.1 * b) * R, t, 0.038 * R, 0.016 * R, 0.016 * R, (a + b) % 2 * 90.0);
  place(s, 0, multiply(about_z(23.0), about_x(3.0)), {0.0, 0.0, -0.05 * R});
  return p;
}

Phantom thin_pipe(double R) {
  check_radius(R);
  Phantom p;
  auto& s = p.shapes;
  const double radius = 0.3 * R, wall = 0.015 * radius, half_length = 0.8 * R;
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, 0.0}, {radius, radius, half_length}, kCarbonFibre));
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, 0.0}, {radius - wall, radius - wall, half_length}, -kCarbonFibre));
  // An aluminium sleeve round one end and a thin bulkhead inside.
  const double sleeve = radius + 0.02 * R;
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, 0.6 * R}, {sleeve, sleeve, 0.06 * R}, kAluminium));
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, 0.6 * R}, {radius, radius, 0.06 * R}, -kAluminium));
  s.push_back(make(ShapeKind::Cylinder, {0.0, 0.0, -0.3 * R}, {radius - wall, radius - wall, 0.003 * R}, kCarbonFibre));
  place(s, 0, multiply(about_z(30.0), about_x(20.0)), {0.0, 0.0, 0.0});
  return p;
}

Phantom lattice_part(double R) {
  check_radius(R);
  Phantom p;
  auto& s = p.shapes;
  const int cells = 5;
  const double cell = 0.2 * R, half = 0.5 * cells * cell, w = 0.015 * R;  // w: half a strut's width
  auto node = [&](int i) { return -half + i * cell; };
  // Struts along x, y and z through every row of nodes, reaching w past the
  // outer nodes. Where struts cross, the node cube is covered three times:
  // a cube of −2 densities makes it solid once.
  for (int i = 0; i <= cells; ++i)
    for (int j = 0; j <= cells; ++j) {
      s.push_back(make(ShapeKind::Box, {0.0, node(i), node(j)}, {half + w, w, w}, kTitanium));
      s.push_back(make(ShapeKind::Box, {node(i), 0.0, node(j)}, {w, half + w, w}, kTitanium));
      s.push_back(make(ShapeKind::Box, {node(i), node(j), 0.0}, {w, w, half + w}, kTitanium));
    }
  for (int i = 0; i <= cells; ++i)
    for (int j = 0; j <= cells; ++j)
      for (int k = 0; k <= cells; ++k)
        s.push_back(make(ShapeKind::Box, {node(i), node(j), node(k)}, {w, w, w}, -2.0 * kTitanium));
  // The build plate under the bottom layer.
  const double plate = 0.025 * R;
  s.push_back(make(ShapeKind::Box, {0.0, 0.0, -half - w - plate}, {half + w + 0.03 * R, half + w + 0.03 * R, plate},
                   kTitanium));
  // Three pores in struts, between nodes.
  const double pore = 0.006 * R;
  s.push_back(make(ShapeKind::Ellipsoid, {node(0) + 0.5 * cell, node(2), node(3)}, {pore, pore, pore}, -kTitanium));
  s.push_back(make(ShapeKind::Ellipsoid, {node(4), node(1) + 0.3 * cell, node(5)}, {pore, pore, pore}, -kTitanium));
  s.push_back(
      make(ShapeKind::Ellipsoid, {node(2), node(3), node(1) + 0.6 * cell}, {pore, 1.5 * pore, pore}, -kTitanium));
  place(s, 0, multiply(about_z(17.0), about_y(6.0)), {0.0, 0.0, 0.03 * R});
  return p;
}

Phantom fine_wires(double R, double w) {
  check_radius(R);
  if (!(w > 0.0) || !std::isfinite(w) || w > 0.04 * R)
    throw std::invalid_argument("phantom: the wire width must be positive and at most 4 % of the field's radius");
  Phantom p;
  auto& s = p.shapes;
  const double h = 0.5 * w;  // half a wire's width
  // A copper grating: 9 wires along x, gaps of one width between them.
  for (int n = 0; n < 9; ++n)
    s.push_back(make(ShapeKind::Box, {0.0, -0.3 * R + (n - 4) * 2.0 * w, 0.25 * R}, {0.45 * R, h, h}, kCopper));
  // A steel grating across it, lower down: 9 wires along y.
  for (int n = 0; n < 9; ++n)
    s.push_back(make(ShapeKind::Box, {0.2 * R + (n - 4) * 2.0 * w, 0.0, -0.25 * R}, {h, 0.45 * R, h}, kSteel));
  // Two aluminium sheets one width thick with a gap of one width between
  // them, standing across the field.
  for (double side : {-1.0, 1.0})
    s.push_back(make(ShapeKind::Box, {-0.35 * R + side * w, 0.1 * R, 0.0}, {h, 0.3 * R, 0.35 * R}, kAluminium));
  // Lone wires in air, far from everything else: steel along z and along two
  // diagonals, brass along y, and a plastic one (near the threshold).
  s.push_back(rod({0.45 * R, 0.35 * R, -0.6 * R}, {0.45 * R, 0.35 * R, 0.6 * R}, h, kSteel));
  s.push_back(rod({-0.5 * R, -0.5 * R, -0.5 * R}, {0.3 * R, 0.0, 0.55 * R}, h, kSteel));
  s.push_back(rod({0.6 * R, -0.3 * R, 0.6 * R}, {0.0, -0.6 * R, -0.2 * R}, h, kSteel));
  s.push_back(make(ShapeKind::Box, {-0.15 * R, 0.0, 0.6 * R}, {h, 0.5 * R, h}, kBrass));
  s.push_back(make(ShapeKind::Box, {0.0, 0.55 * R, -0.55 * R}, {0.5 * R, h, h}, kPlastic));
  // Turned so that no wire runs along the voxel grid.
  place(s, 0, multiply(about_z(11.0), about_x(4.0)), {0.0, 0.0, 0.0});
  return p;
}

Phantom fine_wires(double R) { return fine_wires(R, R / 128.0); }

std::vector<std::string> phantom_names() {
  return {"shepp-logan", "pencil-holder", "connector-board", "computer-board",
          "thin-pipe",   "lattice-part",  "fine-wires"};
}

Phantom named_phantom(const std::string& name, double fov_radius) {
  static const std::pair<const char*, Phantom (*)(double)> kMakers[] = {
      {"shepp-logan", shepp_logan_3d},    {"pencil-holder", pencil_holder}, {"connector-board", connector_board},
      {"computer-board", computer_board}, {"thin-pipe", thin_pipe},         {"lattice-part", lattice_part},
      {"fine-wires", fine_wires}};
  for (const auto& [known, maker] : kMakers)
    if (name == known) return maker(fov_radius);
  std::string list;
  for (const std::string& n : phantom_names()) list += (list.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown phantom \"" + name + "\"; known phantoms: " + list);
}

}  // namespace ivol::recon
