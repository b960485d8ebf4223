#include "ivol/recon/geometry.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace ivol::recon {
namespace {

struct Frame {
  Vec3 u;       // detector columns
  Vec3 toward;  // from the isocentre toward the source
};

Frame frame_of(double angle) {
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  return {{c, s, 0.0}, {s, -c, 0.0}};
}

double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

}  // namespace

Vec3 ScanGeometry::source_position(std::size_t view) const {
  const View& v = views.at(view);
  const Frame f = frame_of(v.angle);
  return {v.source_to_isocenter * f.toward[0] + v.source_offset_u * f.u[0],
          v.source_to_isocenter * f.toward[1] + v.source_offset_u * f.u[1], v.source_offset_v};
}

Vec3 ScanGeometry::pixel_position(std::size_t view, double column, double row) const {
  const View& v = views.at(view);
  const Frame f = frame_of(v.angle);
  const double u = (column - 0.5 * (detector.columns - 1)) * detector.pitch_u + v.detector_offset_u;
  const double w = (row - 0.5 * (detector.rows - 1)) * detector.pitch_v + v.detector_offset_v;
  const double depth = v.source_to_isocenter - v.source_to_detector;  // along `toward`
  return {depth * f.toward[0] + u * f.u[0], depth * f.toward[1] + u * f.u[1], w};
}

ScanGeometry::Projected ScanGeometry::project(std::size_t view, const Vec3& point) const {
  const View& v = views.at(view);
  const Frame f = frame_of(v.angle);
  const double a = dot(point, f.u);
  const double b = point[2];
  const double c = dot(point, f.toward);
  const double magnification = v.source_to_detector / (v.source_to_isocenter - c);
  const double u = v.source_offset_u + (a - v.source_offset_u) * magnification;
  const double w = v.source_offset_v + (b - v.source_offset_v) * magnification;
  return {(u - v.detector_offset_u) / detector.pitch_u + 0.5 * (detector.columns - 1),
          (w - v.detector_offset_v) / detector.pitch_v + 0.5 * (detector.rows - 1), magnification};
}

void ScanGeometry::validate() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("scan geometry: " + what); };
  if (detector.columns <= 0 || detector.rows <= 0) fail("detector size must be positive");
  if (!(detector.pitch_u > 0.0) || !(detector.pitch_v > 0.0)) fail("detector pixel pitch must be positive");
  if (views.empty()) fail("there are no views");
  for (std::size_t i = 0; i < views.size(); ++i) {
    const View& v = views[i];
    const std::string where = "view " + std::to_string(i) + ": ";
    if (!std::isfinite(v.angle)) fail(where + "angle is not finite");
    if (!(v.source_to_isocenter > 0.0)) fail(where + "source-to-isocentre distance must be positive");
    if (!(v.source_to_detector > v.source_to_isocenter))
      fail(where + "source-to-detector distance must exceed the source-to-isocentre distance");
    if (!std::isfinite(v.detector_offset_u) || !std::isfinite(v.detector_offset_v) ||
        !std::isfinite(v.source_offset_u) || !std::isfinite(v.source_offset_v))
      fail(where + "offsets must be finite");
  }
}

ScanGeometry circular_scan(const Detector& detector, std::size_t view_count, double source_to_isocenter,
                           double source_to_detector, double arc, double first_angle, double detector_offset_u,
                           double detector_offset_v) {
  ScanGeometry g;
  g.detector = detector;
  g.views.resize(view_count);
  // As RTK's simulated geometries: the views split the arc evenly, so a full
  // circle does not repeat its first view.
  const double step = view_count > 0 ? arc / static_cast<double>(view_count) : 0.0;
  for (std::size_t i = 0; i < view_count; ++i) {
    View& v = g.views[i];
    v.angle = first_angle + step * static_cast<double>(i);
    v.source_to_isocenter = source_to_isocenter;
    v.source_to_detector = source_to_detector;
    v.detector_offset_u = detector_offset_u;
    v.detector_offset_v = detector_offset_v;
  }
  return g;
}

ScanGeometry reduce_scan(const ScanGeometry& geometry, unsigned view_step, unsigned bin) {
  ScanGeometry reduced;
  const Detector& d = geometry.detector;
  reduced.detector = {d.columns / static_cast<int>(bin), d.rows / static_cast<int>(bin), d.pitch_u * bin,
                      d.pitch_v * bin};
  // Pixels left over at the high end are dropped, which moves the merged
  // detector's centre by half of what was dropped.
  const double shift_u = 0.5 * d.pitch_u * (static_cast<double>(bin) * reduced.detector.columns - d.columns);
  const double shift_v = 0.5 * d.pitch_v * (static_cast<double>(bin) * reduced.detector.rows - d.rows);
  for (std::size_t v = 0; v < geometry.view_count(); v += view_step) {
    View view = geometry.views[v];
    view.detector_offset_u += shift_u;
    view.detector_offset_v += shift_v;
    reduced.views.push_back(view);
  }
  return reduced;
}

VolumeGrid VolumeGrid::centred(std::array<std::uint32_t, 3> size, double voxel) {
  return centred(size, Vec3{voxel, voxel, voxel});
}

VolumeGrid VolumeGrid::centred(std::array<std::uint32_t, 3> size, const Vec3& voxel) {
  VolumeGrid g;
  g.size = size;
  g.voxel_size = voxel;
  for (int a = 0; a < 3; ++a) g.origin[a] = -0.5 * (static_cast<double>(size[a]) - 1.0) * voxel[a];
  return g;
}

void VolumeGrid::validate() const {
  for (int a = 0; a < 3; ++a) {
    if (size[a] == 0) throw std::invalid_argument("volume grid: size must be positive on every axis");
    if (!(voxel_size[a] > 0.0)) throw std::invalid_argument("volume grid: voxel size must be positive");
    if (!std::isfinite(origin[a])) throw std::invalid_argument("volume grid: origin must be finite");
  }
}

}  // namespace ivol::recon
