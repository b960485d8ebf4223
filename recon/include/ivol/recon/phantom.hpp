// Analytic phantoms: sums of ellipsoids, finite elliptic cylinders and boxes
// with constant densities, whose line integrals are computed exactly (ray –
// quadric and ray – slab intersections), so that a reconstruction can be
// compared with the object it was made from.
//
// Units: positions in mm in the scan's world frame (z is the rotation axis,
// geometry.hpp), densities are linear attenuation coefficients in 1/mm, line
// integrals are dimensionless (mm · 1/mm). Densities add where shapes
// overlap, as in RTK's geometric phantoms: a hollow part is a shape plus a
// shape of the opposite density.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/projections.hpp"

namespace ivol::recon {

// Row-major 3×3 rotation taking shape-local vectors to world vectors.
using Rotation = std::array<double, 9>;
constexpr Rotation kIdentityRotation{1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};

// Rotation by `radians` about `axis` (need not be unit length), right-handed.
Rotation rotation_about_axis(const Vec3& axis, double radians);

enum class ShapeKind {
  Ellipsoid,  // (x/a)² + (y/b)² + (z/c)² ≤ 1 in the local frame
  Cylinder,   // (x/a)² + (y/b)² ≤ 1 and |z| ≤ c: elliptic section, axis along local z
  Box,        // |x| ≤ a, |y| ≤ b, |z| ≤ c
};

struct Shape {
  ShapeKind kind = ShapeKind::Ellipsoid;
  Vec3 centre{0.0, 0.0, 0.0};     // mm, world
  Vec3 half_size{1.0, 1.0, 1.0};  // (a, b, c) above, mm; all must be positive
  Rotation rotation = kIdentityRotation;
  double density = 0.0;  // 1/mm, added to whatever else covers the point
};

struct Phantom {
  std::vector<Shape> shapes;

  // Sum of the densities of the shapes containing `p` (boundaries included).
  double density(const Vec3& p) const;
  // ∫ density along the segment from `from` to `to`: the sum over shapes of
  // density × length of the segment inside the shape, exact up to rounding.
  double line_integral(const Vec3& from, const Vec3& to) const;

  // Throws std::invalid_argument naming the shape when a semi-axis is not
  // positive, a value is not finite or a rotation is not orthonormal.
  void validate() const;
};

// Line integrals from the source of `view` to each detector pixel, rows ×
// columns floats, columns fastest. With supersampling s > 1, each pixel is the
// mean of s×s rays through the centres of an s×s split of the pixel.
void project_view(const Phantom& phantom, const ScanGeometry& geometry, std::size_t view, float* image,
                  int supersampling = 1);

// Every view of the scan, computed on `threads` threads (0: one per hardware
// thread).
InMemoryProjections project_scan(const Phantom& phantom, const ScanGeometry& geometry, int supersampling = 1,
                                 unsigned threads = 0);

// Replaces each line integral p by −log(max(I, 0.5) / I0) where I is drawn
// from Poisson(I0 · exp(−p)): photon counting noise for `incident_photons`
// (I0) photons per pixel. Values are drawn in order from one
// std::mt19937_64 seeded with `seed`, so a seed gives the same noise on every
// run with the same standard library.
void add_poisson_noise(float* line_integrals, std::size_t count, double incident_photons, std::uint64_t seed);

// Density at the centres of voxels of z-slices [k_begin, k_end) of `grid`
// ((k_end − k_begin) · nx · ny floats, i fastest), or with supersampling s > 1
// the mean of s³ samples at the centres of an s×s×s split of each voxel.
// Runs on one thread per hardware thread, a slice at a time.
void voxelize(const Phantom& phantom, const VolumeGrid& grid, std::uint32_t k_begin, std::uint32_t k_end, float* out,
              int supersampling = 1);

// ---------------------------------------------------------------------------
// Named phantoms. Each fits in a cylinder of radius 0.95 · fov_radius about z
// and |z| ≤ 0.95 · fov_radius, so it lies in the field of view of a scan
// reconstructing a field of that radius.

// RTK's 3D Shepp–Logan phantom (rtk::SheppLoganPhantom, drawn with
// SetPhantomScale(scale)): ten ellipsoids whose sizes and centres are RTK's
// table times `scale` mm, with RTK's densities (the outer ellipsoid 2, the
// skull interior 1.02). Moved to this frame, whose z is RTK's y.
Phantom shepp_logan_3d(double scale);

// A plastic cup with a closed base holding three tilted pencils (wood around a
// graphite core), a pen with a metal ball tip and a steel paper clip on the
// base.
Phantom pencil_holder(double fov_radius);

// An upright circuit board (glass-epoxy) tilted a few degrees, with two
// plastic connector housings carrying rows of brass pins through the board,
// surface-mount parts with metal end caps, copper traces and mounting holes.
Phantom connector_board(double fov_radius);

// A single-board computer lying almost flat: a thin board with a processor
// and a memory package on grids of solder balls, a pin header, metal connector
// shells and scattered small parts.
Phantom computer_board(double fov_radius);

// A carbon-fibre tube with a wall of 1.5 % of its radius, tilted 20° from z,
// with an aluminium sleeve near one end.
Phantom thin_pipe(double fov_radius);

// An additively manufactured titanium lattice: a cubic grid of square struts
// along the three axes (5 cells a side) standing on a solid plate, turned so
// that no face is aligned with the grid.
Phantom lattice_part(double fov_radius);

// Wires and sheets one `wire_width` thick with gaps of one width: a copper
// and a steel grating (9 square wires each, gaps of one width), two aluminium
// sheets with a gap of one width, and lone wires in air (steel along z and
// two diagonals, brass, one of plastic), all turned off the voxel grid. The
// one-argument form makes them fov_radius / 128 wide: one voxel at 256³ over
// the field.
Phantom fine_wires(double fov_radius, double wire_width);
Phantom fine_wires(double fov_radius);

// "shepp-logan" (scale = fov_radius, so the outer ellipsoid spans the field),
// "pencil-holder", "connector-board", "computer-board", "thin-pipe",
// "lattice-part", "fine-wires". Throws std::invalid_argument listing the known names.
Phantom named_phantom(const std::string& name, double fov_radius);
std::vector<std::string> phantom_names();

}  // namespace ivol::recon
