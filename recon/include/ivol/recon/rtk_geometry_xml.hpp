// RTK's circular cone-beam geometry files (rtk::ThreeDCircularProjectionGeometry
// as its XML writer stores it, format versions 2 and 3), read into and
// written from our ScanGeometry.
//
// Frames. RTK's world (x, y, z) has y as the rotation axis; ours has z:
//   X = x,  Y = −z,  Z = y          (and back: x = X, y = Z, z = −Y).
// With that renaming a gantry angle θ, the source offsets and the distances
// mean the same in both (geometry.hpp): RTK rotates a point by Ry(−θ), so
// that x_rot = x·cos θ − z·sin θ = X·cos θ + Y·sin θ (our û component) and
// z_rot = x·sin θ + z·cos θ = X·sin θ − Y·cos θ (our "toward the source"
// component), and puts the source at (SourceOffsetX, SourceOffsetY, SID) of
// the rotated frame.
//
// Detector. RTK projects onto physical coordinates of the projection image,
//   u = (x_rot − sx)·SDD / (SID − z_rot) + sx − ProjectionOffsetX
//   v = (y_rot − sy)·SDD / (SID − z_rot) + sy − ProjectionOffsetY,
// and the image's pixel i sits at u = origin_u + i·pitch_u (identity
// direction). Our project() puts column i at u' = (i − (columns − 1)/2)·pitch_u
// + detector_offset_u with u' = u + ProjectionOffsetX, so
//   detector_offset_u = ProjectionOffsetX + origin_u + (columns − 1)/2 · pitch_u
//   detector_offset_v = ProjectionOffsetY + origin_v + (rows − 1)/2 · pitch_v
// source_offset_u = SourceOffsetX, source_offset_v = SourceOffsetY, angles
// from degrees to radians. The detector size and pitch are not in RTK's file
// (they come from the projection images), hence the parameters; a centred RTK
// projection image has origin −(n − 1)/2 · pitch and gives offset =
// ProjectionOffset.
#pragma once

#include <string>

#include "ivol/recon/geometry.hpp"

namespace ivol::recon {

// Reads an RTK geometry file. The root element is <RTKThreeDCircularGeometry
// version="2"> or "3" (element names compared without regard to case, as RTK
// does). Parameter elements outside a <Projection> set values for the
// projections that follow; inside one they override them. As in RTK's own
// reader, a value set inside a <Projection> stays in force for the following
// projections until set again (files written by RTK never depend on this: they
// repeat a varying parameter in every projection). Defaults: offsets and tilt
// angles 0; GantryAngle (or its old name Angle), SourceToIsocenterDistance
// and SourceToDetectorDistance have none. Collimation elements are read and
// ignored (they do not change the geometry).
//
// Refused, with a std::runtime_error naming the file, the projection number
// (0-based) and the element: a non-zero InPlaneAngle or OutOfPlaneAngle
// (tilted detectors), SourceToDetectorDistance 0 or not finite (RTK's
// parallel beam), a non-zero RadiusCylindricalDetector (curved detector), a
// missing GantryAngle / SourceToIsocenterDistance / SourceToDetectorDistance,
// a value that is not a number, an unknown element, no projections, and a
// geometry our ScanGeometry::validate() refuses (for example SDD ≤ SID).
// Malformed XML, a wrong root element or version: std::runtime_error naming
// the file and the element (or the parser's message and byte offset).
//
// Independent check: when a <Projection> carries its <Matrix> (RTK writes
// one for every projection), a few world points are projected with our
// ScanGeometry::project() and with the file's 3×4 matrix (after the frame
// change above and the origin/pitch of the image); the two detector positions
// must agree to 1e-6 relative (of the larger of the position, the origin and
// the detector's extent, in mm), otherwise the file's parameters and matrix
// disagree, or our conventions do, and the read is refused naming the
// projection and Matrix.
ScanGeometry read_rtk_geometry_xml(const std::string& path, const Detector& detector, double projection_origin_u,
                                   double projection_origin_v);

// Writes `geometry` as RTK's version-3 file, laid out as RTK's writer does: a
// parameter equal in all views is written once before the projections (and
// not at all when it is 0, the default, for offsets), the others in every
// <Projection> after its GantryAngle (in degrees), each projection with its
// 3×4 <Matrix> computed from RTK's definition. `projection_origin_u/v` is the
// origin RTK's projection images will have (physical position of pixel 0);
// the inverse of the conversion above gives the ProjectionOffsets. Numbers are
// written with enough digits to read back exactly. Throws
// std::invalid_argument for a geometry validate() refuses, std::runtime_error
// naming the file when it cannot be written.
void write_rtk_geometry_xml(const std::string& path, const ScanGeometry& geometry, double projection_origin_u,
                            double projection_origin_v);

}  // namespace ivol::recon
