// Shapes ready for intersection tests, shared by phantom.cpp and
// phantom_projection.cpp (not installed).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "ivol/recon/phantom.hpp"

namespace ivol::recon::phantom_detail {

inline double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3 minus(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// A shape ready for intersection tests: q = to_unit · (p − centre) takes a
// world point to the frame where the shape is the unit ball, the unit
// cylinder or the cube [−1, 1]³; to_unit = diag(1 / half_size) · rotationᵀ.
struct Prepared {
  ShapeKind kind;
  Vec3 centre;
  std::array<double, 9> to_unit;
  double bound_squared;  // a sphere of this squared radius about the centre holds the shape
  double density;
};

inline Vec3 apply(const std::array<double, 9>& m, const Vec3& v) {
  return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
          m[6] * v[0] + m[7] * v[1] + m[8] * v[2]};
}

inline Prepared prepare(const Shape& s) {
  Prepared p{s.kind, s.centre, {}, 0.0, s.density};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) p.to_unit[r * 3 + c] = s.rotation[c * 3 + r] / s.half_size[r];
  const Vec3& h = s.half_size;
  switch (s.kind) {
    case ShapeKind::Ellipsoid:
      p.bound_squared = std::pow(std::max({h[0], h[1], h[2]}), 2);
      break;
    case ShapeKind::Cylinder:
      p.bound_squared = std::pow(std::max(h[0], h[1]), 2) + h[2] * h[2];
      break;
    case ShapeKind::Box:
      p.bound_squared = dot(h, h);
      break;
  }
  p.bound_squared *= 1.0 + 1e-12;  // rounding must not reject a grazing ray
  return p;
}

inline std::vector<Prepared> prepare_all(const Phantom& phantom) {
  phantom.validate();
  std::vector<Prepared> out;
  out.reserve(phantom.shapes.size());
  for (const Shape& s : phantom.shapes) out.push_back(prepare(s));
  return out;
}

// Parameter range [t0, t1] of a line, empty when t0 > t1.
struct Interval {
  double t0 = -std::numeric_limits<double>::infinity();
  double t1 = std::numeric_limits<double>::infinity();
};

inline void make_empty(Interval& iv) { iv = {1.0, 0.0}; }

// Keeps the part of the line o + t·e (one coordinate) with |o + t·e| ≤ 1.
inline void clip_slab(double o, double e, Interval& iv) {
  if (e == 0.0) {
    if (std::abs(o) > 1.0) make_empty(iv);
    return;
  }
  double a = (-1.0 - o) / e;
  double b = (1.0 - o) / e;
  if (a > b) std::swap(a, b);
  iv.t0 = std::max(iv.t0, a);
  iv.t1 = std::min(iv.t1, b);
}

// Keeps the part with |o + t·e|² ≤ 1 over the first n coordinates (3: the unit
// ball; 2: the infinite unit cylinder). The roots are found from the closest
// point to the centre, which stays accurate for grazing rays.
inline void clip_ball(const Vec3& o, const Vec3& e, int n, Interval& iv) {
  double ee = 0.0;
  double oe = 0.0;
  for (int k = 0; k < n; ++k) {
    ee += e[k] * e[k];
    oe += o[k] * e[k];
  }
  const double tm = ee > 0.0 ? -oe / ee : 0.0;
  double d2 = 0.0;
  for (int k = 0; k < n; ++k) d2 += (o[k] + tm * e[k]) * (o[k] + tm * e[k]);
  if (d2 > 1.0) {
    make_empty(iv);
    return;
  }
  if (ee == 0.0) return;  // parallel to the cylinder's axis and inside it
  const double half = std::sqrt((1.0 - d2) / ee);
  iv.t0 = std::max(iv.t0, tm - half);
  iv.t1 = std::min(iv.t1, tm + half);
}

// Where the line relative + t·direction (relative to the shape's centre) is
// inside the shape.
inline Interval intersect(const Prepared& s, const Vec3& relative, const Vec3& direction) {
  const Vec3 o = apply(s.to_unit, relative);
  const Vec3 e = apply(s.to_unit, direction);
  Interval iv;
  switch (s.kind) {
    case ShapeKind::Ellipsoid:
      clip_ball(o, e, 3, iv);
      break;
    case ShapeKind::Cylinder:
      clip_ball(o, e, 2, iv);
      clip_slab(o[2], e[2], iv);
      break;
    case ShapeKind::Box:
      for (int k = 0; k < 3; ++k) clip_slab(o[k], e[k], iv);
      break;
  }
  return iv;
}

// Density × the part of [0, 1] for which from + t·d is inside shape `s`: the
// density × chord divided by |d|; 0 when the line misses the shape's bounding
// sphere.
inline double chord_fraction(const Prepared& s, const Vec3& from, const Vec3& d, double length_squared) {
  const Vec3 relative = minus(from, s.centre);
  const Vec3 c = cross(relative, d);
  if (dot(c, c) > s.bound_squared * length_squared) return 0.0;
  const Interval iv = intersect(s, relative, d);
  const double t0 = std::max(iv.t0, 0.0);
  const double t1 = std::min(iv.t1, 1.0);
  return t1 > t0 ? s.density * (t1 - t0) : 0.0;
}

}  // namespace ivol::recon::phantom_detail
