#include "ivol/recon/phantom.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "phantom_shapes.hpp"

namespace ivol::recon {

using phantom_detail::chord_fraction;
using phantom_detail::dot;
using phantom_detail::minus;
using phantom_detail::prepare;

Rotation rotation_about_axis(const Vec3& axis, double radians) {
  const double n = std::sqrt(dot(axis, axis));
  if (!(n > 0.0) || !std::isfinite(n)) throw std::invalid_argument("rotation: the axis must be a non-zero vector");
  const double x = axis[0] / n, y = axis[1] / n, z = axis[2] / n;
  const double c = std::cos(radians), s = std::sin(radians), t = 1.0 - c;
  // Rodrigues' formula.
  return {t * x * x + c,     t * x * y - s * z, t * x * z + s * y, t * x * y + s * z, t * y * y + c,
          t * y * z - s * x, t * x * z - s * y, t * y * z + s * x, t * z * z + c};
}

double Phantom::density(const Vec3& p) const {
  double sum = 0.0;
  for (const Shape& s : shapes) {
    const Vec3 r = minus(p, s.centre);
    Vec3 q;
    for (int a = 0; a < 3; ++a)
      q[a] = (s.rotation[a] * r[0] + s.rotation[3 + a] * r[1] + s.rotation[6 + a] * r[2]) / s.half_size[a];
    bool inside = false;
    switch (s.kind) {
      case ShapeKind::Ellipsoid:
        inside = dot(q, q) <= 1.0;
        break;
      case ShapeKind::Cylinder:
        inside = q[0] * q[0] + q[1] * q[1] <= 1.0 && std::abs(q[2]) <= 1.0;
        break;
      case ShapeKind::Box:
        inside = std::abs(q[0]) <= 1.0 && std::abs(q[1]) <= 1.0 && std::abs(q[2]) <= 1.0;
        break;
    }
    if (inside) sum += s.density;
  }
  return sum;
}

double Phantom::line_integral(const Vec3& from, const Vec3& to) const {
  const Vec3 d = minus(to, from);
  const double length_squared = dot(d, d);
  if (length_squared == 0.0) return 0.0;
  double sum = 0.0;
  for (const Shape& s : shapes) sum += chord_fraction(prepare(s), from, d, length_squared);
  return sum * std::sqrt(length_squared);
}

void Phantom::validate() const {
  for (std::size_t n = 0; n < shapes.size(); ++n) {
    const Shape& s = shapes[n];
    auto fail = [n](const std::string& what) {
      throw std::invalid_argument("phantom: shape " + std::to_string(n) + ": " + what);
    };
    for (int a = 0; a < 3; ++a) {
      if (!(s.half_size[a] > 0.0) || !std::isfinite(s.half_size[a])) fail("semi-axes must be positive and finite");
      if (!std::isfinite(s.centre[a])) fail("centre must be finite");
    }
    if (!std::isfinite(s.density)) fail("density must be finite");
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        double rtr = 0.0;
        for (int k = 0; k < 3; ++k) rtr += s.rotation[k * 3 + r] * s.rotation[k * 3 + c];
        if (!(std::abs(rtr - (r == c ? 1.0 : 0.0)) <= 1e-9)) fail("rotation is not orthonormal");
      }
  }
}

}  // namespace ivol::recon
