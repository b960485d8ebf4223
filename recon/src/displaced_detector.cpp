#include "ivol/recon/displaced_detector.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "fdk_plan.hpp"

namespace ivol::recon {
namespace {

// A detector coordinate as it would be without the source's sideways offset:
// the offset tilts the central ray, and the weighting is defined on the rays'
// angles from the line through the isocentre (RTK's untilted coordinate).
double untilted(const View& v, double u) {
  const double sdd = v.source_to_detector;
  const double sx = v.source_offset_u;
  const double hypotenuse = std::sqrt(sdd * sdd + sx * sx);
  return hypotenuse * (sdd * u / (sdd * sdd + (sx - u) * sx));
}

double first_column_u(const Detector& d, const View& v) {
  return -0.5 * (d.columns - 1) * d.pitch_u + v.detector_offset_u;
}

}  // namespace

std::string DisplacedDetector::describe() const {
  std::ostringstream text;
  if (!weighted()) {
    text << "detector centred on the axis (" << inferior << " to " << superior
         << " mm): no displaced-detector weighting";
    return text.str();
  }
  text << "displaced detector (" << inferior << " to " << superior << " mm): Wang weighting over +-" << overlap
       << " mm around the axis, " << padding << " zero columns added on the " << (side > 0 ? "-u" : "+u") << " side";
  return text.str();
}

DisplacedDetector analyse_displaced_detector(const ScanGeometry& geometry) {
  const Detector& d = geometry.detector;
  DisplacedDetector result;
  result.inferior = -std::numeric_limits<double>::infinity();
  result.superior = std::numeric_limits<double>::infinity();
  for (const View& v : geometry.views) {
    const double first = first_column_u(d, v);
    const double last = first + (d.columns - 1) * d.pitch_u;
    result.inferior = std::max(result.inferior, untilted(v, first));
    result.superior = std::min(result.superior, untilted(v, last));
  }
  // Where the rotation axis itself projects, in every view: with a source
  // offset that is not u = 0 (the ray through the isocentre comes from the
  // offset source), so it is checked on its own.
  for (std::size_t v = 0; v < geometry.view_count(); ++v) {
    const double column = geometry.project(v, Vec3{0.0, 0.0, 0.0}).column;
    if (column < 0.0 || column > d.columns - 1) {
      std::ostringstream text;
      text << "the detector does not see the rotation axis in view " << v << ": the axis projects to column " << column
           << " of 0 to " << d.columns - 1
           << " (check the detector offset, the source offset, --offset or the projection origin)";
      throw std::invalid_argument(text.str());
    }
  }
  if (result.inferior > 0.0 || result.superior < 0.0) {
    std::ostringstream text;
    text << "the detector does not see the rotation axis in every view: the columns every view shares span "
         << result.inferior << " to " << result.superior
         << " mm on the detector, which must include 0 (check the detector offset, --offset or the projection "
            "origin)";
    throw std::invalid_argument(text.str());
  }
  const double width = result.superior - result.inferior;
  if (std::abs(result.inferior + result.superior) < 0.1 * width) return result;

  result.side = result.inferior + result.superior > 0.0 ? 1 : -1;
  result.overlap = std::min(-result.inferior, result.superior);
  const detail::ScanShape shape = detail::analyse_scan(geometry);
  if (shape.short_scan) {
    std::ostringstream text;
    text << "the detector is displaced (" << result.inferior << " to " << result.superior
         << " mm): its weighting needs views all round the circle, but this scan covers " << shape.arc * 180.0 / M_PI
         << " degrees";
    throw std::invalid_argument(text.str());
  }
  // The missing side must reach as far from the axis as the measured one.
  const double missing = std::max(result.superior, -result.inferior) - result.overlap;
  result.padding = static_cast<int>(std::ceil(missing / d.pitch_u)) + 2;
  return result;
}

ScanGeometry widen_for_displaced_detector(const ScanGeometry& geometry, const DisplacedDetector& displaced) {
  ScanGeometry wide = geometry;
  if (!displaced.weighted()) return wide;
  wide.detector.columns += displaced.padding;
  // Added on the low side (side +1) the first measured column moves `padding`
  // columns in; either way the centre moves by half the padding.
  const double shift = 0.5 * displaced.padding * geometry.detector.pitch_u;
  for (View& v : wide.views) v.detector_offset_u += displaced.side > 0 ? -shift : shift;
  return wide;
}

double displaced_detector_weight(const DisplacedDetector& displaced, const View& view, double u) {
  if (!displaced.weighted()) return 1.0;
  const double theta = displaced.overlap;
  const double sdd = view.source_to_detector;
  const double sx = view.source_offset_u;
  const double hypotenuse = std::sqrt(sdd * sdd + sx * sx);
  const double l = untilted(view, u) * static_cast<double>(displaced.side);
  if (l <= -theta) return 0.0;
  if (l >= theta) return 2.0;
  return 1.0 + std::sin(M_PI * std::atan(l / hypotenuse) / (2.0 * std::atan(theta / hypotenuse)));
}

DisplacedDetectorProjections::DisplacedDetectorProjections(ProjectionSource& source, const ScanGeometry& geometry,
                                                           const DisplacedDetector& displaced)
    : source_(source), geometry_(geometry), displaced_(displaced) {
  if (source.columns() != geometry.detector.columns || source.rows() != geometry.detector.rows)
    throw std::invalid_argument("displaced detector: the projections' size differs from the geometry's detector");
}

DisplacedDetectorProjections::DisplacedDetectorProjections(std::unique_ptr<ProjectionSource> source,
                                                           const ScanGeometry& geometry,
                                                           const DisplacedDetector& displaced)
    : DisplacedDetectorProjections(*source, geometry, displaced) {
  owned_ = std::move(source);
}

void DisplacedDetectorProjections::read_rows(std::size_t view, int row_begin, int row_end, float* out) {
  const int measured = source_.columns();
  const int wide = columns();
  const std::size_t rows = static_cast<std::size_t>(row_end - row_begin);
  measured_.resize(rows * static_cast<std::size_t>(measured));
  source_.read_rows(view, row_begin, row_end, measured_.data());

  const View& v = geometry_.views[view];
  weights_.resize(static_cast<std::size_t>(measured));
  const double first = first_column_u(geometry_.detector, v);
  for (int c = 0; c < measured; ++c)
    weights_[c] = static_cast<float>(displaced_detector_weight(displaced_, v, first + c * geometry_.detector.pitch_u));

  const int lead = displaced_.side > 0 ? displaced_.padding : 0;
  for (std::size_t r = 0; r < rows; ++r) {
    float* row = out + r * static_cast<std::size_t>(wide);
    const float* in = measured_.data() + r * static_cast<std::size_t>(measured);
    std::fill(row, row + wide, 0.0F);
    for (int c = 0; c < measured; ++c) row[lead + c] = in[c] * weights_[c];
  }
}

}  // namespace ivol::recon
