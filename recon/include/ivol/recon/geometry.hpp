// Circular cone-beam scan geometry and the reconstruction grid.
//
// Conventions (docs/geometry.md has the drawing): world coordinates in mm,
// right-handed, z is the rotation axis. At gantry angle θ the source sits at
//   S(θ) = SID · (sin θ, −cos θ, 0) + source_offset_u · û(θ) + source_offset_v · ẑ
// and the detector plane is perpendicular to the central ray at distance SDD
// from the source, with
//   û(θ) = (cos θ, sin θ, 0)   (columns, increasing index)
//   v̂    = (0, 0, 1)           (rows, increasing index).
// θ grows counter-clockwise seen from +z. This is RTK's geometry with its y
// axis renamed z (rtk_geometry_xml.hpp gives the mapping), so a scan moved
// over from RTK keeps its angles and offsets.
//
// Detector coordinates (u, v) are in mm in the detector plane, measured from
// the point where the line through the isocentre perpendicular to the
// detector meets it (the central ray when the source is not offset). Pixel
// (column i, row j) has its centre at
//   u = (i − (columns − 1)/2) · pitch_u + detector_offset_u
//   v = (j − (rows − 1)/2) · pitch_v + detector_offset_v
// i.e. a detector offset moves the whole detector, as RTK's projection offset
// does with a centred projection origin.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ivol::recon {

using Vec3 = std::array<double, 3>;

struct Detector {
  int columns = 0;
  int rows = 0;
  double pitch_u = 1.0;  // mm per column
  double pitch_v = 1.0;  // mm per row
};

// One projection's pose. Everything is per view so that scans with a wobbling
// detector or uneven angles (RTK's geometry files) are represented exactly.
struct View {
  double angle = 0.0;                // gantry angle θ in radians
  double source_to_isocenter = 0.0;  // SID, mm
  double source_to_detector = 0.0;   // SDD, mm
  double detector_offset_u = 0.0;    // mm
  double detector_offset_v = 0.0;    // mm
  double source_offset_u = 0.0;      // mm, along û(θ)
  double source_offset_v = 0.0;      // mm, along z
};

struct ScanGeometry {
  Detector detector;
  std::vector<View> views;

  std::size_t view_count() const { return views.size(); }

  // World position of the source of view `view`.
  Vec3 source_position(std::size_t view) const;
  // World position of the centre of detector pixel (column, row) of `view`;
  // fractional indices give points between centres.
  Vec3 pixel_position(std::size_t view, double column, double row) const;
  // Detector (column, row) index, fractional, where the ray from the source
  // through `point` meets the detector; also the depth ratio SDD / distance
  // from the source plane, the magnification of the point.
  struct Projected {
    double column;
    double row;
    double magnification;
  };
  Projected project(std::size_t view, const Vec3& point) const;

  // Throws std::invalid_argument naming the field when the geometry is not
  // usable (no views, non-positive sizes, SDD ≤ SID, ...).
  void validate() const;
};

// A uniform circular scan: `view_count` views at first_angle + i·arc/view_count
// (as RTK's simulated geometries: a full circle does not repeat its first
// view), one SID/SDD and detector offset for all views.
ScanGeometry circular_scan(const Detector& detector, std::size_t view_count, double source_to_isocenter,
                           double source_to_detector, double arc, double first_angle = 0.0,
                           double detector_offset_u = 0.0, double detector_offset_v = 0.0);

// The scan ReducedProjections(source, view_step, bin) sees: every
// view_step-th view, bin × bin pixels merged into one whose centre is the
// centre of the pixels it merges.
ScanGeometry reduce_scan(const ScanGeometry& geometry, unsigned view_step, unsigned bin);

// The reconstruction grid: voxel (i, j, k) has its centre at
// origin + (i·voxel_size[0], j·voxel_size[1], k·voxel_size[2]), i fastest in
// memory; k runs along the rotation axis.
struct VolumeGrid {
  std::array<std::uint32_t, 3> size{0, 0, 0};
  Vec3 voxel_size{1.0, 1.0, 1.0};
  Vec3 origin{0.0, 0.0, 0.0};

  std::uint64_t voxel_count() const { return std::uint64_t{size[0]} * size[1] * size[2]; }
  Vec3 voxel_centre(double i, double j, double k) const {
    return {origin[0] + i * voxel_size[0], origin[1] + j * voxel_size[1], origin[2] + k * voxel_size[2]};
  }
  // A grid of `size` voxels of `voxel` mm centred on the isocentre.
  static VolumeGrid centred(std::array<std::uint32_t, 3> size, double voxel);
  // The same with a voxel size per axis (anisotropic voxels, e.g. finer in-plane).
  static VolumeGrid centred(std::array<std::uint32_t, 3> size, const Vec3& voxel);
  void validate() const;
};

}  // namespace ivol::recon
