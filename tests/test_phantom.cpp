// Analytic phantoms against independent references: closed-form chords,
// numerical quadrature of the density, the scan geometry's own projection of
// a point, photon statistics, sphere volumes and RTK's Shepp–Logan quadrics
// evaluated the way RTK evaluates them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "ivol/recon/phantom.hpp"

namespace {

using namespace ivol::recon;

constexpr double kPi = 3.14159265358979323846;

Shape shape(ShapeKind kind, const Vec3& centre, const Vec3& half, double density,
            const Rotation& rotation = kIdentityRotation) {
  return Shape{kind, centre, half, rotation, density};
}

Phantom one(const Shape& s) { return Phantom{{s}}; }

Vec3 along(const Vec3& p, const Vec3& d, double t) { return {p[0] + t * d[0], p[1] + t * d[1], p[2] + t * d[2]}; }

Vec3 unit(const Vec3& v) {
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / n, v[1] / n, v[2] / n};
}

// Rotations written out here rather than taken from the library.
Rotation turn_z(double a) { return {std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1}; }
Rotation turn_x(double a) { return {1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a)}; }
Rotation times(const Rotation& a, const Rotation& b) {
  Rotation m{};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 3; ++k) m[r * 3 + c] += a[r * 3 + k] * b[k * 3 + c];
  return m;
}
Vec3 apply(const Rotation& m, const Vec3& v) {
  return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
          m[6] * v[0] + m[7] * v[1] + m[8] * v[2]};
}
Vec3 apply_transposed(const Rotation& m, const Vec3& v) {
  return {m[0] * v[0] + m[3] * v[1] + m[6] * v[2], m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
          m[2] * v[0] + m[5] * v[1] + m[8] * v[2]};
}

TEST(PhantomChords, Sphere) {
  const Vec3 c{1, 2, 3};
  const Phantom p = one(shape(ShapeKind::Ellipsoid, c, {7, 7, 7}, 0.5));
  EXPECT_NEAR(p.line_integral({-20, 2, 3}, {30, 2, 3}), 7.0, 1e-12);
  EXPECT_NEAR(p.line_integral({30, 2, 3}, {-20, 2, 3}), 7.0, 1e-12);
  EXPECT_NEAR(p.line_integral({-20, 5, 3}, {30, 5, 3}), 0.5 * 2 * std::sqrt(49.0 - 9.0), 1e-12);
  EXPECT_EQ(p.line_integral({-20, 9.01, 3}, {30, 9.01, 3}), 0.0);
  const Vec3 n = unit({0.3, -0.8, 0.5});
  EXPECT_NEAR(p.line_integral(along(c, n, -20), along(c, n, 25)), 7.0, 1e-12);
  EXPECT_NEAR(p.line_integral(along(c, n, -20), along(c, n, 2)), 0.5 * 9.0, 1e-12);  // ends inside
  EXPECT_NEAR(p.line_integral(along(c, n, -1), along(c, n, 3)), 0.5 * 4.0, 1e-12);   // wholly inside
  EXPECT_EQ(p.line_integral(c, c), 0.0);
}

TEST(PhantomChords, AxisAlignedBox) {
  const Vec3 c{5, -1, 0};
  const Phantom p = one(shape(ShapeKind::Box, c, {2, 3, 4}, 2.0));
  EXPECT_NEAR(p.line_integral({-10, -1, 0}, {10, -1, 0}), 2.0 * 4, 1e-12);
  EXPECT_NEAR(p.line_integral({6.9, -10, 3.9}, {6.9, 10, 3.9}), 2.0 * 6, 1e-12);
  EXPECT_EQ(p.line_integral({7.1, -10, 0}, {7.1, 10, 0}), 0.0);
  const Vec3 diagonal = unit({2, 3, 4});
  EXPECT_NEAR(p.line_integral(along(c, diagonal, -9), along(c, diagonal, 9)), 2.0 * 2 * std::sqrt(29.0), 1e-12);
  const Vec3 xy = unit({1, 1, 0});  // leaves through the x faces, at |t| = 2√2
  EXPECT_NEAR(p.line_integral(along(c, xy, -9), along(c, xy, 9)), 2.0 * 4 * std::sqrt(2.0), 1e-12);
}

TEST(PhantomChords, EllipticCylinder) {
  const Vec3 c{0, 0, 1};
  const Phantom p = one(shape(ShapeKind::Cylinder, c, {3, 5, 4}, 1.0));
  EXPECT_NEAR(p.line_integral({1, 1, -20}, {1, 1, 20}), 8.0, 1e-12);  // along the axis
  EXPECT_NEAR(p.line_integral({-9, 0, 1}, {9, 0, 1}), 6.0, 1e-12);    // across, both radii
  EXPECT_NEAR(p.line_integral({0, -9, 1}, {0, 9, 1}), 10.0, 1e-12);
  EXPECT_NEAR(p.line_integral({-9, 4, 2}, {9, 4, 2}), 2 * 3 * std::sqrt(1 - 0.64), 1e-12);
  EXPECT_EQ(p.line_integral({-9, 0, 5.01}, {9, 0, 5.01}), 0.0);
  for (double degrees : {30.0, 60.0}) {  // oblique through the centre: caps or side, whichever is first
    const double a = degrees * kPi / 180;
    const Vec3 n{std::sin(a), 0, std::cos(a)};
    EXPECT_NEAR(p.line_integral(along(c, n, -30), along(c, n, 30)), std::min(2 * 4 / std::cos(a), 2 * 3 / std::sin(a)),
                1e-12)
        << degrees;
  }
}

TEST(PhantomChords, RotatedShapeEqualsUnrotatedShapeWithRotatedRay) {
  const Rotation q = times(turn_z(0.7), turn_x(-1.1));
  const Rotation library = rotation_about_axis({0, 0, 2}, 0.7);
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(library[k], turn_z(0.7)[k], 1e-15);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-12, 12);
  const Vec3 c{2, -3, 1};
  for (ShapeKind kind : {ShapeKind::Ellipsoid, ShapeKind::Cylinder, ShapeKind::Box}) {
    const Phantom turned = one(shape(kind, c, {3, 6, 4}, 1.5, q));
    const Phantom straight = one(shape(kind, c, {3, 6, 4}, 1.5));
    int hits = 0;
    for (int n = 0; n < 200; ++n) {
      const Vec3 a{u(rng), u(rng), u(rng)}, b{u(rng), u(rng), u(rng)};
      auto back = [&](const Vec3& p) {
        const Vec3 r = apply_transposed(q, {p[0] - c[0], p[1] - c[1], p[2] - c[2]});
        return Vec3{c[0] + r[0], c[1] + r[1], c[2] + r[2]};
      };
      const double expected = straight.line_integral(back(a), back(b));
      ASSERT_NEAR(turned.line_integral(a, b), expected, 1e-10);
      hits += expected > 0;
    }
    EXPECT_GT(hits, 25);
    // Along the turned local z axis through the centre: the c semi-axis.
    const Vec3 z = apply(q, {0, 0, 1});
    EXPECT_NEAR(turned.line_integral(along(c, z, -20), along(c, z, 20)), 1.5 * 8, 1e-11);
  }
}

// A sphere about `c` holding the shape, from its data alone.
double bound(const Shape& s) {
  return std::sqrt(s.half_size[0] * s.half_size[0] + s.half_size[1] * s.half_size[1] + s.half_size[2] * s.half_size[2]);
}

TEST(PhantomLineIntegrals, MatchQuadratureOfDensityForEveryNamedPhantom) {
  const double radius = 50;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const std::string& name : phantom_names()) {
    const Phantom p = named_phantom(name, radius);
    std::vector<Vec3> solid;  // centres of the shapes that add material
    for (const Shape& s : p.shapes)
      if (s.density > 0) solid.push_back(s.centre);
    double signal = 0, allowed = 0;
    for (int ray = 0; ray < 6; ++ray) {
      // A random direction through a random part's centre.
      Vec3 d;
      do d = {u(rng), u(rng), u(rng)};
      while (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > 1 || d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 0.01);
      d = unit(d);
      const Vec3 mid = solid[static_cast<std::size_t>((u(rng) + 1) / 2 * solid.size()) % solid.size()];
      const Vec3 a = along(mid, d, -1.5 * radius), b = along(mid, d, 1.5 * radius);
      const int steps = 20000;
      const double h = 3 * radius / steps;
      double sum = 0, lowest = 0, jumps = 0, previous = 0;
      for (int k = 0; k < steps; ++k) {
        const double rho = p.density(along(a, d, (k + 0.5) * h));
        sum += rho * h;
        lowest = std::min(lowest, rho);
        jumps += std::abs(rho - previous);
        previous = rho;
      }
      // The midpoint rule is off by at most h/2 · |jump| at each
      // discontinuity; twice that covers two crossings between samples.
      const double tolerance = jumps * h + 1e-9;
      EXPECT_NEAR(p.line_integral(a, b), sum, tolerance) << name << " ray " << ray;
      EXPECT_GE(lowest, -1e-12) << name << ": negative density on ray " << ray;
      signal += std::abs(sum);
      allowed += tolerance;
    }
    EXPECT_GT(signal, 20 * allowed) << name << ": the rays missed the phantom";
  }
}

ScanGeometry offset_scan() {
  ScanGeometry g = circular_scan({64, 48, 0.5, 0.6}, 4, 200, 350, 2 * kPi, 0.3, 3.1, -2.3);
  g.views[1].angle = 2.0;
  g.views[2].angle = 4.1;
  for (std::size_t v = 0; v < g.views.size(); ++v) {
    g.views[v].source_offset_u = 5.0 - 2.0 * v;
    g.views[v].source_offset_v = -4.0 + 1.5 * v;
  }
  return g;
}

TEST(PhantomProjection, PointBlobLandsWhereTheGeometryProjectsIt) {
  const ScanGeometry g = offset_scan();
  const Vec3 point{2.5, -1.5, 2};
  const Phantom p = one(shape(ShapeKind::Ellipsoid, point, {0.6, 0.6, 0.6}, 1.0));
  std::vector<float> image(64 * 48);
  for (std::size_t v = 0; v < g.view_count(); ++v) {
    project_view(p, g, v, image.data(), 4);
    const auto peak = std::max_element(image.begin(), image.end()) - image.begin();
    const ScanGeometry::Projected expected = g.project(v, point);
    ASSERT_TRUE(expected.column > 8 && expected.column < 56 && expected.row > 8 && expected.row < 40) << "view " << v;
    ASSERT_GT(image[peak], 0.5f);
    EXPECT_LE(std::abs(peak % 64 - expected.column), 1.0) << "view " << v;
    EXPECT_LE(std::abs(peak / 64 - expected.row), 1.0) << "view " << v;
    double sum = 0, column = 0, row = 0;
    for (int j = 0; j < 48; ++j)
      for (int i = 0; i < 64; ++i) {
        sum += image[j * 64 + i];
        column += i * image[j * 64 + i];
        row += j * image[j * 64 + i];
      }
    EXPECT_NEAR(column / sum, expected.column, 0.05) << "view " << v;
    EXPECT_NEAR(row / sum, expected.row, 0.05) << "view " << v;
  }
}

TEST(PhantomProjection, CentralRayThroughSphereIsItsDiameter) {
  const ScanGeometry g = circular_scan({33, 33, 1.0, 1.0}, 3, 300, 500, 2 * kPi, 0.4);
  const Phantom p = one(shape(ShapeKind::Ellipsoid, {0, 0, 0}, {10, 10, 10}, 0.25));
  std::vector<float> image(33 * 33);
  for (std::size_t v = 0; v < 3; ++v) {
    project_view(p, g, v, image.data());
    EXPECT_NEAR(image[16 * 33 + 16], 0.25 * 20, 1e-5);
    EXPECT_EQ(image[0], 0.0f);
  }
}

TEST(PhantomProjection, DetectorIntegralIsVolumeTimesMagnificationSquared) {
  // ∫ p dA = ∫ density · SDD² / (cos γ · depth²) dV, which for a small
  // sphere is ρ V m² to about 3 r² / (5 depth²), m the magnification of its
  // centre.
  const ScanGeometry g = circular_scan({64, 64, 0.5, 0.5}, 1, 300, 600, 2 * kPi, 0.9);
  const double r = 4;
  const Phantom p = one(shape(ShapeKind::Ellipsoid, {0.2, -0.1, 0.3}, {r, r, r}, 1.0));
  std::vector<float> image(64 * 64);
  project_view(p, g, 0, image.data(), 4);
  double sum = 0;
  for (float x : image) sum += x * 0.25;
  const double m = g.project(0, {0.2, -0.1, 0.3}).magnification;
  EXPECT_NEAR(sum / (4.0 / 3.0 * kPi * r * r * r * m * m), 1.0, 3e-4);
}

TEST(PhantomProjection, SupersamplingAveragesSubRaysAcrossThePixel) {
  const ScanGeometry g = offset_scan();
  const Phantom p = pencil_holder(12);
  std::vector<float> image(64 * 48);
  project_view(p, g, 2, image.data(), 3);
  const Vec3 source = g.source_position(2);
  for (auto [i, j] : {std::pair{20, 20}, std::pair{33, 25}, std::pair{40, 10}, std::pair{5, 47}}) {
    double sum = 0;
    for (double a : {-1.0 / 3, 0.0, 1.0 / 3})
      for (double b : {-1.0 / 3, 0.0, 1.0 / 3}) sum += p.line_integral(source, g.pixel_position(2, i + a, j + b));
    EXPECT_NEAR(image[j * 64 + i], sum / 9, 1e-5) << i << "," << j;
  }
  EXPECT_GT(*std::max_element(image.begin(), image.end()), 0.1f);
}

TEST(PhantomProjection, EveryPixelIsTheLineIntegralToItsCentre) {
  const ScanGeometry g = offset_scan();
  std::vector<float> image(64 * 48);
  for (const std::string& name : phantom_names()) {
    const Phantom p = named_phantom(name, 14);
    project_view(p, g, 1, image.data());
    const Vec3 source = g.source_position(1);
    int covered = 0;
    for (int j = 0; j < 48; ++j)
      for (int i = 0; i < 64; ++i) {
        const double expected = p.line_integral(source, g.pixel_position(1, i, j));
        ASSERT_NEAR(image[j * 64 + i], expected, 1e-6 + 1e-6 * expected) << name << " pixel " << i << "," << j;
        covered += expected > 0;
      }
    EXPECT_GT(covered, 100) << name;
  }
}

TEST(PhantomProjection, ScanOnThreadsEqualsViewByView) {
  const ScanGeometry g = offset_scan();
  const Phantom p = computer_board(15);
  const InMemoryProjections scan = project_scan(p, g, 1, 3);
  std::vector<float> image(64 * 48);
  for (std::size_t v = 0; v < g.view_count(); ++v) {
    project_view(p, g, v, image.data());
    EXPECT_TRUE(std::equal(image.begin(), image.end(), scan.view_data(v))) << "view " << v;
  }
}

TEST(PhantomNoise, PoissonMeanVarianceClampAndSeed) {
  const std::size_t n = 100000;
  const double i0 = 1000;
  std::vector<float> p(n, 1.0f);
  add_poisson_noise(p.data(), n, i0, 42);
  double mean = 0, square = 0;
  for (float x : p) {
    const double counted = i0 * std::exp(-static_cast<double>(x));
    ASSERT_NEAR(counted, std::round(counted), 1e-3);
    mean += counted;
    square += counted * counted;
  }
  mean /= n;
  const double variance = square / n - mean * mean;
  const double lambda = i0 * std::exp(-1.0);
  EXPECT_NEAR(mean, lambda, 5 * std::sqrt(lambda / n));
  EXPECT_NEAR(variance, lambda, 5 * lambda * std::sqrt(2.0 / n));

  std::vector<float> again(n, 1.0f), other(n, 1.0f);
  add_poisson_noise(again.data(), n, i0, 42);
  add_poisson_noise(other.data(), n, i0, 43);
  EXPECT_EQ(p, again);
  EXPECT_NE(p, other);

  // No photon counted: half a photon, p' = log(2 I0).
  std::vector<float> dark(100, 40.0f);
  add_poisson_noise(dark.data(), dark.size(), 100, 1);
  for (float x : dark) EXPECT_FLOAT_EQ(x, static_cast<float>(std::log(200.0)));
  // Few photons: P(0) = exp(−λ).
  std::vector<float> faint(20000, 5.0f);
  add_poisson_noise(faint.data(), faint.size(), 100, 2);
  const double zeros =
      std::count_if(faint.begin(), faint.end(), [](float x) { return std::abs(x - std::log(200.0)) < 1e-5; });
  EXPECT_NEAR(zeros / faint.size(), std::exp(-100 * std::exp(-5.0)), 0.02);
  EXPECT_THROW(add_poisson_noise(faint.data(), 1, 0.0, 1), std::invalid_argument);
}

TEST(PhantomVoxelize, SphereVolume) {
  const double r = 10;
  const Phantom p = one(shape(ShapeKind::Ellipsoid, {0.37, -0.21, 0.13}, {r, r, r}, 1.0));
  const VolumeGrid grid = VolumeGrid::centred({28, 28, 28}, 1.0);
  std::vector<float> out(grid.voxel_count());
  const double volume = 4.0 / 3.0 * kPi * r * r * r;
  voxelize(p, grid, 0, 28, out.data());
  EXPECT_NEAR(std::count(out.begin(), out.end(), 1.0f), volume, 0.01 * volume);
  voxelize(p, grid, 0, 28, out.data(), 4);
  double sum = 0;
  for (float x : out) sum += x;
  EXPECT_NEAR(sum, volume, 0.003 * volume);
}

TEST(PhantomVoxelize, EqualsDensityAtVoxelCentresAndSlabsAgree) {
  const double radius = 20;
  const VolumeGrid grid{{21, 19, 20}, {2.0, 2.1, 1.9}, {-20.3, -19.1, -18.2}};
  const std::size_t slice = 21 * 19;
  for (const std::string& name : phantom_names()) {
    const Phantom p = named_phantom(name, radius);
    std::vector<float> whole(grid.voxel_count()), part(slice * 7);
    voxelize(p, grid, 0, 20, whole.data());
    int mismatches = 0, nonzero = 0;
    for (std::uint32_t k = 0; k < 20; ++k)
      for (std::uint32_t j = 0; j < 19; ++j)
        for (std::uint32_t i = 0; i < 21; ++i) {
          const double expected = p.density(grid.voxel_centre(i, j, k));
          mismatches += std::abs(whole[k * slice + j * 21 + i] - expected) > 1e-6;
          nonzero += expected != 0;
        }
    EXPECT_LE(mismatches, 1) << name;
    // fine-wires' wires are radius / 128 thin: few centres of 2 mm voxels fall in them.
    EXPECT_GT(nonzero, name == "fine-wires" ? 0 : 10) << name;
    voxelize(p, grid, 9, 16, part.data());
    EXPECT_TRUE(std::equal(part.begin(), part.end(), whole.begin() + 9 * slice)) << name;
  }
  EXPECT_THROW(voxelize(Phantom{}, grid, 5, 21, nullptr), std::out_of_range);
}

// RTK's table (rtk::SheppLoganPhantom): semi-axes, centre, angle about RTK's
// y in degrees, density; evaluated as RTK's quadric
//   A'x² + B y² + C'z² + E' x z ≤ 1 about the centre, with A' = A cos² + C sin²,
//   C' = A sin² + C cos², E' = 2 sin cos (A − C), A = 1/a_x², B = 1/a_y², C = 1/a_z².
struct RtkRow {
  double a[3], c[3], angle, density;
};
const RtkRow kRtk[] = {
    {{0.69, 0.90, 0.92}, {0, 0, 0}, 0, 2.0},
    {{0.6624, 0.880, 0.874}, {0, 0, 0}, 0, -0.98},
    {{0.41, 0.21, 0.16}, {-0.22, -0.25, 0}, 108, -0.02},
    {{0.31, 0.22, 0.11}, {0.22, -0.25, 0}, 72, -0.02},
    {{0.21, 0.50, 0.25}, {0, -0.25, 0.35}, 0, 0.02},
    {{0.046, 0.046, 0.046}, {0, -0.25, 0.10}, 0, 0.02},
    {{0.046, 0.02, 0.023}, {-0.08, -0.25, -0.65}, 0, 0.01},
    {{0.046, 0.02, 0.023}, {0.06, -0.25, -0.65}, 90, 0.01},
    {{0.056, 0.1, 0.04}, {0.06, 0.625, -0.105}, 90, 0.02},
    {{0.056, 0.1, 0.056}, {0, 0.625, 0.1}, 0, -0.02},
};

// Density at an RTK-frame point for phantom scale s.
double rtk_density(double x, double y, double z, double s) {
  double sum = 0;
  for (const RtkRow& e : kRtk) {
    const double A = 1 / (e.a[0] * e.a[0] * s * s), B = 1 / (e.a[1] * e.a[1] * s * s),
                 C = 1 / (e.a[2] * e.a[2] * s * s);
    const double co = std::cos(e.angle * kPi / 180), si = std::sin(e.angle * kPi / 180);
    const double dx = x - e.c[0] * s, dy = y - e.c[1] * s, dz = z - e.c[2] * s;
    const double q = (A * co * co + C * si * si) * dx * dx + B * dy * dy + (A * si * si + C * co * co) * dz * dz +
                     2 * si * co * (A - C) * dx * dz;
    if (q <= 1) sum += e.density;
  }
  return sum;
}

TEST(PhantomSheppLogan, MatchesRtkQuadricsInOurFrame) {
  const double s = 116;
  const Phantom p = shepp_logan_3d(s);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-s, s);
  int inner = 0;
  for (int n = 0; n < 20000; ++n) {
    const Vec3 ours{u(rng), u(rng), u(rng)};
    // Ours (X, Y, Z) is RTK's (x, y, z) = (X, Z, −Y).
    const double expected = rtk_density(ours[0], ours[2], -ours[1], s);
    ASSERT_NEAR(p.density(ours), expected, 1e-12) << ours[0] << " " << ours[1] << " " << ours[2];
    inner += std::abs(expected - 1.0) < 0.005 || std::abs(expected - 1.04) < 0.005;
  }
  EXPECT_GT(inner, 200);  // points in the small ellipsoids

  // Known points, by hand from the table, through voxelize (a 1-voxel grid
  // centred on each). RTK point (x, y, z) → ours (x, −z, y).
  const double tilt = 108 * kPi / 180;
  const double ex = -0.22 + 0.35 * std::cos(tilt), ez = 0.35 * std::sin(tilt);  // in ellipsoid 3, off its centre
  const struct {
    double x, y, z, value;
  } known[] = {
      {0, 0, 0, 1.02},              // inside the skull: 2 − 0.98
      {0.68, 0, 0, 2.0},            // the skull's shell
      {0.8, 0, 0, 0.0},             // outside
      {-0.22, -0.25, 0, 1.0},       // ellipsoid 3: 1.02 − 0.02
      {ex, -0.25, ez, 1.0},         // along ellipsoid 3's tilted long axis (1.02 if turned the wrong way)
      {0, -0.25, 0.35, 1.04},       // ellipsoid 5
      {0.06, 0.625, -0.105, 1.04},  // ellipsoid 9
      {0, 0.625, 0.1, 1.0},         // ellipsoid 10
  };
  for (const auto& k : known) {
    const VolumeGrid one_voxel{{1, 1, 1}, {1, 1, 1}, {k.x * s, -k.z * s, k.y * s}};
    float value = -1;
    voxelize(p, one_voxel, 0, 1, &value);
    EXPECT_NEAR(value, k.value, 1e-6) << k.x << " " << k.y << " " << k.z;
  }
  // The outer ellipsoid spans the field: RTK's semi-axis 0.92 lies along −Y.
  // ellipsoid 5 too: x = y = 0 is 0.25 from its centre in RTK's y, half its 0.5.
  EXPECT_NEAR(p.line_integral({0, -2 * s, 0}, {0, 2 * s, 0}),
              2 * (2.0 * 0.92 - 0.98 * 0.874 + 0.02 * 0.25 * std::sqrt(0.75)) * s, 1e-9);
}

// Largest distance from z and largest |z| of a shape, from its corners (box),
// its two rim ellipses (cylinder) or its surface (ellipsoid, sampled).
std::pair<double, double> extent(const Shape& s) {
  std::vector<Vec3> local;
  const Vec3& h = s.half_size;
  if (s.kind == ShapeKind::Box) {
    for (int c = 0; c < 8; ++c)
      local.push_back({(c & 1) ? h[0] : -h[0], (c & 2) ? h[1] : -h[1], (c & 4) ? h[2] : -h[2]});
  } else if (s.kind == ShapeKind::Cylinder) {
    for (int a = 0; a < 2000; ++a)
      for (double z : {-h[2], h[2]})
        local.push_back({h[0] * std::cos(a * kPi / 1000), h[1] * std::sin(a * kPi / 1000), z});
  } else {
    for (int a = 0; a <= 100; ++a)
      for (int b = 0; b < 200; ++b) {
        const double th = a * kPi / 100, ph = b * kPi / 100;
        local.push_back({h[0] * std::sin(th) * std::cos(ph), h[1] * std::sin(th) * std::sin(ph), h[2] * std::cos(th)});
      }
  }
  double radial = 0, axial = 0;
  for (const Vec3& l : local) {
    const Vec3 w = apply(s.rotation, l);
    radial = std::max(radial, std::hypot(s.centre[0] + w[0], s.centre[1] + w[1]));
    axial = std::max(axial, std::abs(s.centre[2] + w[2]));
  }
  return {radial, axial};
}

TEST(PhantomLibrary, EveryPhantomFitsTheFieldOfView) {
  const double radius = 40;
  for (const std::string& name : phantom_names()) {
    const Phantom p = named_phantom(name, radius);
    ASSERT_FALSE(p.shapes.empty()) << name;
    EXPECT_NO_THROW(p.validate()) << name;
    double radial = 0, axial = 0;
    for (const Shape& s : p.shapes) {
      const auto [r, z] = extent(s);
      radial = std::max(radial, r);
      axial = std::max(axial, z);
    }
    EXPECT_LE(radial, 0.95 * radius) << name;
    EXPECT_LE(axial, 0.95 * radius) << name;
    EXPECT_GT(std::max(radial, axial), 0.4 * radius) << name;
  }
}

TEST(PhantomLibrary, NamesAndRefusals) {
  EXPECT_EQ(phantom_names().size(), 7u);
  try {
    named_phantom("teapot", 10);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    for (const std::string& name : phantom_names()) EXPECT_NE(std::string(e.what()).find(name), std::string::npos);
  }
  EXPECT_THROW(named_phantom("thin-pipe", 0), std::invalid_argument);
  EXPECT_THROW(named_phantom("shepp-logan", -1), std::invalid_argument);
  const ScanGeometry g = offset_scan();
  std::vector<float> image(64 * 48);
  Phantom flat = one(shape(ShapeKind::Box, {0, 0, 0}, {1, 0, 1}, 1));
  EXPECT_THROW(project_view(flat, g, 0, image.data()), std::invalid_argument);
  Phantom skew = one(shape(ShapeKind::Box, {0, 0, 0}, {1, 1, 1}, 1, {1, 0.1, 0, 0, 1, 0, 0, 0, 1}));
  EXPECT_THROW(project_view(skew, g, 0, image.data()), std::invalid_argument);
  EXPECT_THROW(project_view(one(shape(ShapeKind::Box, {0, 0, 0}, {1, 1, 1}, 1)), g, 9, image.data()),
               std::out_of_range);
  EXPECT_THROW(project_view(Phantom{}, g, 0, image.data(), 0), std::invalid_argument);
}

}  // namespace
