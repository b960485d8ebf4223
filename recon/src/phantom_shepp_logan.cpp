// RTK's 3D Shepp–Logan phantom, moved into this library's frame.
#include <cmath>
#include <stdexcept>

#include "ivol/recon/phantom.hpp"

namespace ivol::recon {
namespace {

// RTK's table (rtk::SheppLoganPhantom, src/rtkSheppLoganPhantom.cxx): the
// semi-axes and the centre in RTK's frame for a phantom scale of 1, the angle
// in degrees of RTK's rotation about its y axis, and the density. (RTK's older
// DrawSheppLoganFilter gave the ninth ellipsoid a y semi-axis of 0.01; the
// phantom RTK draws and projects today has 0.1.)
struct RtkEllipsoid {
  double axis[3];
  double centre[3];
  double angle;
  double density;
};

// clang-format off
constexpr RtkEllipsoid kSheppLogan[] = {
    {{0.69,   0.90,  0.92},  { 0.0,   0.0,    0.0},     0.0,  2.0},
    {{0.6624, 0.880, 0.874}, { 0.0,   0.0,    0.0},     0.0, -0.98},
    {{0.41,   0.21,  0.16},  {-0.22, -0.25,   0.0},   108.0, -0.02},
    {{0.31,   0.22,  0.11},  { 0.22, -0.25,   0.0},    72.0, -0.02},
    {{0.21,   0.50,  0.25},  { 0.0,  -0.25,   0.35},    0.0,  0.02},
    {{0.046,  0.046, 0.046}, { 0.0,  -0.25,   0.10},    0.0,  0.02},
    {{0.046,  0.02,  0.023}, {-0.08, -0.25,  -0.65},    0.0,  0.01},
    {{0.046,  0.02,  0.023}, { 0.06, -0.25,  -0.65},   90.0,  0.01},
    {{0.056,  0.1,   0.04},  { 0.06,  0.625, -0.105},  90.0,  0.02},
    {{0.056,  0.1,   0.056}, { 0.0,   0.625,  0.1},     0.0, -0.02},
};
// clang-format on

}  // namespace

// RTK's world has y as the rotation axis; ours has z. A point (x, y, z) of
// RTK's is (X, Y, Z) = (x, −z, y) here, a proper rotation (by +90° about x).
// Each ellipsoid's own axes follow the same map, so its semi-axes (a_x, a_y,
// a_z) become (a_x, a_z, a_y). RTK turns an ellipsoid by θ with the quadric
//   (cos²θ/a_x² + sin²θ/a_z²) x² + (sin²θ/a_x² + cos²θ/a_z²) z²
//     + 2 sinθ cosθ (1/a_x² − 1/a_z²) x z ≤ 1
// (about its centre), whose a_x semi-axis lies along RTK's (cos θ, 0, sin θ),
// that is along (cos θ, −sin θ, 0) here: the ellipsoid is turned by −θ about
// our z axis (clockwise seen from +z). The phantom scale multiplies the
// semi-axes and the centres, as RTK's SetPhantomScale does.
Phantom shepp_logan_3d(double scale) {
  if (!(scale > 0.0) || !std::isfinite(scale))
    throw std::invalid_argument("shepp-logan phantom: the scale must be positive and finite");
  Phantom p;
  for (const RtkEllipsoid& e : kSheppLogan) {
    Shape s;
    s.kind = ShapeKind::Ellipsoid;
    s.centre = {scale * e.centre[0], -scale * e.centre[2], scale * e.centre[1]};
    s.half_size = {scale * e.axis[0], scale * e.axis[2], scale * e.axis[1]};
    s.rotation = rotation_about_axis({0.0, 0.0, 1.0}, -e.angle * 3.14159265358979323846 / 180.0);
    s.density = e.density;
    p.shapes.push_back(s);
  }
  return p;
}

}  // namespace ivol::recon
