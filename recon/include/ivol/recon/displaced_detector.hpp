// Displaced (offset, "half-fan") detectors: a full-circle scan whose detector
// is shifted sideways so that it sees one side of the object wholly and the
// other side only near the rotation axis. Each ray through the object is then
// measured once, by one of two opposite views, except in a band around the
// axis that both see. Wang's weighting (Med. Phys. 29, 2002) gives every ray
// a total weight of 2 across the pair: a smooth ramp from 0 to 2 across the
// band both views see, 2 beyond it. The weighted projections are extended
// with zeros on the missing side, so that the ramp filter's response spreads
// into the half the detector did not see, as it would for a full detector.
//
// This is RTK's DisplacedDetectorImageFilter's rule (same corners, same
// "less than 10 % off centre: nothing to do" tolerance), so a scan moved over
// from RTK reconstructs the same way.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/projections.hpp"

namespace ivol::recon {

struct DisplacedDetector {
  // Detector edges every view shares, mm in untilted detector coordinates
  // (pixel centres of the first and last column, detector offset included).
  double inferior = 0.0;
  double superior = 0.0;
  // +1: the detector extends towards +u (the −u side is missing), −1: the
  // opposite, 0: centred within 10 % of its width, no weighting needed.
  int side = 0;
  double overlap = 0.0;  // half-width of the band both sides see, mm
  int padding = 0;       // zero columns added on the missing side

  bool weighted() const { return side != 0; }
  std::string describe() const;
};

// Throws std::invalid_argument naming the numbers when the detector does not
// see the rotation axis in some view (no weighting can recover that), and
// when a displaced detector is used on a scan that is not a full circle.
DisplacedDetector analyse_displaced_detector(const ScanGeometry& geometry);

// The geometry of the widened detector: `padding` more columns on the missing
// side, detector offsets moved so that the measured columns stay where they
// were. Returns the geometry unchanged when no weighting is needed.
ScanGeometry widen_for_displaced_detector(const ScanGeometry& geometry, const DisplacedDetector& displaced);

// Wang's weight, in [0, 2], of the pixel at detector coordinate u (mm) of a
// view.
double displaced_detector_weight(const DisplacedDetector& displaced, const View& view, double u);

// The projections of `source` weighted and widened: reads the measured rows
// and writes them with their weights into the widened detector's columns,
// zeros in the padding.
class DisplacedDetectorProjections : public ProjectionSource {
 public:
  DisplacedDetectorProjections(ProjectionSource& source, const ScanGeometry& geometry,
                               const DisplacedDetector& displaced);
  // The same, owning the measured projections.
  DisplacedDetectorProjections(std::unique_ptr<ProjectionSource> source, const ScanGeometry& geometry,
                               const DisplacedDetector& displaced);
  int columns() const override { return source_.columns() + displaced_.padding; }
  int rows() const override { return source_.rows(); }
  std::size_t view_count() const override { return source_.view_count(); }
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override;

 private:
  std::unique_ptr<ProjectionSource> owned_;
  ProjectionSource& source_;
  ScanGeometry geometry_;  // the measured detector's
  DisplacedDetector displaced_;
  std::vector<float> measured_;
  std::vector<float> weights_;
};

}  // namespace ivol::recon
