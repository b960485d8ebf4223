// Wang's displaced-detector weighting, checked against its definition: the
// two rays of an opposite pair weigh 2 together, the weights run from 0 to 2
// across the band both views see, the widened detector keeps every measured
// column where it was, and the cases no weighting can fix are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <stdexcept>

#include "ivol/recon/displaced_detector.hpp"

namespace ivol::recon {
namespace {

ScanGeometry scan_with_offset(double offset_u, double arc = 2 * M_PI) {
  return circular_scan({100, 8, 2.0, 2.0}, 90, 500.0, 1000.0, arc, 0.0, offset_u, 0.0);
}

TEST(DisplacedDetector, CentredDetectorNeedsNothing) {
  const ScanGeometry g = scan_with_offset(9.0);  // 9 mm of a 198 mm detector: under 10 %
  const DisplacedDetector d = analyse_displaced_detector(g);
  EXPECT_FALSE(d.weighted());
  EXPECT_EQ(d.padding, 0);
  EXPECT_EQ(widen_for_displaced_detector(g, d).detector.columns, 100);
  EXPECT_EQ(displaced_detector_weight(d, g.views[0], 40.0), 1.0);
}

TEST(DisplacedDetector, OppositeRaysWeighTwoTogether) {
  for (const double offset : {70.0, -70.0}) {
    SCOPED_TRACE(offset);
    const ScanGeometry g = scan_with_offset(offset);
    const DisplacedDetector d = analyse_displaced_detector(g);
    ASSERT_TRUE(d.weighted());
    EXPECT_EQ(d.side, offset > 0 ? 1 : -1);
    // Pixel centres span ±99 mm around the offset; the near edge is 29 mm
    // from the axis.
    EXPECT_NEAR(d.overlap, 29.0, 1e-9);
    const View& v = g.views[0];
    for (double u = -150; u <= 150; u += 0.7) {
      const double w = displaced_detector_weight(d, v, u);
      EXPECT_GE(w, 0.0);
      EXPECT_LE(w, 2.0);
      EXPECT_NEAR(w + displaced_detector_weight(d, v, -u), 2.0, 1e-12) << "u = " << u;
    }
    EXPECT_NEAR(displaced_detector_weight(d, v, 0.0), 1.0, 1e-12);
    EXPECT_EQ(displaced_detector_weight(d, v, 40.0 * d.side), 2.0);
    EXPECT_EQ(displaced_detector_weight(d, v, -40.0 * d.side), 0.0);
    // Monotone across the band.
    double previous = -1;
    for (double l = -29; l <= 29; l += 0.5) {
      const double w = displaced_detector_weight(d, v, l * d.side);
      EXPECT_GT(w, previous);
      previous = w;
    }
  }
}

TEST(DisplacedDetector, WidenedDetectorKeepsMeasuredColumnsInPlace) {
  for (const double offset : {70.0, -70.0}) {
    SCOPED_TRACE(offset);
    const ScanGeometry g = scan_with_offset(offset);
    const DisplacedDetector d = analyse_displaced_detector(g);
    const ScanGeometry wide = widen_for_displaced_detector(g, d);
    // The far edge is 169 mm out; the missing side must reach as far.
    EXPECT_GE(d.padding, 70);
    EXPECT_EQ(wide.detector.columns, 100 + d.padding);
    const int lead = d.side > 0 ? d.padding : 0;
    for (std::size_t view : {std::size_t{0}, std::size_t{45}}) {
      for (int c : {0, 50, 99}) {
        const Vec3 a = g.pixel_position(view, c, 3);
        const Vec3 b = wide.pixel_position(view, c + lead, 3);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], 1e-9);
      }
    }

    // The projections: measured columns weighted, zeros in the padding.
    InMemoryProjections p(100, 8, 90);
    std::iota(p.data().begin(), p.data().end(), 1.0F);
    DisplacedDetectorProjections weighted(p, g, d);
    ASSERT_EQ(weighted.columns(), wide.detector.columns);
    std::vector<float> rows(static_cast<std::size_t>(weighted.columns()) * 2);
    weighted.read_rows(7, 3, 5, rows.data());
    const View& v = g.views[7];
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < weighted.columns(); ++c) {
        const int measured = c - lead;
        const float got = rows[static_cast<std::size_t>(r) * weighted.columns() + c];
        if (measured < 0 || measured >= 100) {
          EXPECT_EQ(got, 0.0F);
          continue;
        }
        const double u = (measured - 49.5) * 2.0 + offset;
        const float value = p.view_data(7)[(3 + r) * 100 + measured];
        EXPECT_FLOAT_EQ(got, static_cast<float>(value * displaced_detector_weight(d, v, u)));
      }
  }
}

TEST(DisplacedDetector, DetectorBesideTheAxisIsRefused) {
  try {
    analyse_displaced_detector(scan_with_offset(120.0));  // nearest pixel centre 21 mm past the axis
    FAIL() << "accepted a detector that never sees the axis";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("does not see the rotation axis"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("the axis projects to column -10.5 of 0 to 99"), std::string::npos)
        << e.what();
  }
}

// With a source offset the ray through the axis does not meet the detector
// at u = 0: 3 mm of source offset at a magnification of 2 moves the axis 3 mm
// the other way, off a detector whose last pixel centre is 1 mm past u = 0.
TEST(DisplacedDetector, AxisSeenFromAnOffsetSourceIsChecked) {
  ScanGeometry g = scan_with_offset(-100.0);            // pixel centres -199 .. -1 mm: u = 0 just beyond the last
  for (View& v : g.views) v.detector_offset_u = -98.0;  // -197 .. +1 mm: u = 0 on the detector
  EXPECT_NO_THROW(analyse_displaced_detector(g));
  // u_axis = sx + (0 - sx) * SDD/SID = -sx at a magnification of 2.
  for (View& v : g.views) v.source_offset_u = 3.0;  // u_axis = -3 mm: on the detector
  EXPECT_NO_THROW(analyse_displaced_detector(g));
  for (View& v : g.views) v.source_offset_u = -3.0;  // u_axis = +3 mm, past the last pixel centre (+1 mm)
  try {
    analyse_displaced_detector(g);
    FAIL() << "accepted a detector the axis projects beside";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("the axis projects to column 100 of 0 to 99"), std::string::npos) << e.what();
  }
}

TEST(DisplacedDetector, ShortScanIsRefused) {
  try {
    analyse_displaced_detector(scan_with_offset(70.0, 200.0 * M_PI / 180.0));
    FAIL() << "accepted a displaced detector on a 200 degree scan";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("all round the circle"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace ivol::recon
