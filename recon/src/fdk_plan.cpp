#include "fdk_plan.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace ivol::recon::detail {
namespace {

constexpr double kTwoPi = 2.0 * M_PI;

double wrap(double angle) {
  double a = std::fmod(angle, kTwoPi);
  return a < 0.0 ? a + kTwoPi : a;
}

double degrees(double radians) { return radians * 180.0 / M_PI; }

// Affine functions of the voxel index (i, j, k, 1).
using Affine = std::array<double, 4>;

Affine scaled(const Affine& a, double s) { return {a[0] * s, a[1] * s, a[2] * s, a[3] * s}; }
Affine sum(const Affine& a, const Affine& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]}; }

}  // namespace

ScanShape analyse_scan(const ScanGeometry& geometry) {
  ScanShape shape;
  const std::size_t count = geometry.view_count();
  std::vector<double> wrapped(count);
  for (std::size_t v = 0; v < count; ++v) wrapped[v] = wrap(geometry.views[v].angle);
  std::vector<std::size_t> order(count);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return wrapped[a] < wrapped[b]; });

  // Gap after each sorted view, going round the circle.
  std::vector<double> gap_after(count);
  for (std::size_t s = 0; s < count; ++s) {
    const double here = wrapped[order[s]];
    const double next = s + 1 < count ? wrapped[order[s + 1]] : wrapped[order[0]] + kTwoPi;
    gap_after[s] = next - here;
  }
  std::vector<double> sorted_gaps = gap_after;
  std::nth_element(sorted_gaps.begin(), sorted_gaps.begin() + count / 2, sorted_gaps.end());
  const double median_gap = sorted_gaps[count / 2];
  const std::size_t widest =
      static_cast<std::size_t>(std::max_element(gap_after.begin(), gap_after.end()) - gap_after.begin());
  shape.short_scan = count > 1 && gap_after[widest] > 1.5 * median_gap + 1e-12;

  shape.angular_gaps.assign(count, 0.0);
  if (count == 1) {
    shape.angular_gaps[0] = kTwoPi;
  } else if (!shape.short_scan) {
    for (std::size_t s = 0; s < count; ++s) {
      const double before = gap_after[(s + count - 1) % count];
      shape.angular_gaps[order[s]] = 0.5 * (before + gap_after[s]);
    }
    shape.arc = kTwoPi;
  } else {
    // The scan starts after its widest gap and runs round to just before it.
    const std::size_t first = (widest + 1) % count;
    shape.start_angle = wrapped[order[first]];
    shape.arc = kTwoPi - gap_after[widest];
    for (std::size_t n = 0; n < count; ++n) {
      const std::size_t s = (first + n) % count;
      const double before = n == 0 ? gap_after[s] : gap_after[(s + count - 1) % count];
      const double after = n + 1 == count ? before : gap_after[s];
      shape.angular_gaps[order[s]] = 0.5 * (before + after);
    }
    shape.parker_delta = 0.5 * (shape.arc - M_PI);
  }

  // The fan: the widest column's angle to the central ray, over all views.
  const Detector& d = geometry.detector;
  for (const View& v : geometry.views) {
    for (double column : {0.0, static_cast<double>(d.columns - 1)}) {
      const double u = (column - 0.5 * (d.columns - 1)) * d.pitch_u + v.detector_offset_u - v.source_offset_u;
      shape.fan_half_angle = std::max(shape.fan_half_angle, std::atan(std::abs(u) / v.source_to_detector));
    }
  }
  if (shape.short_scan && shape.parker_delta < shape.fan_half_angle) {
    shape.warnings.push_back("short scan: the arc of " + std::to_string(degrees(shape.arc)) +
                             "° is shorter than 180° plus the fan angle (" +
                             std::to_string(degrees(2.0 * shape.fan_half_angle)) +
                             "°); Parker weights cannot complete the data and the outer field of view will show "
                             "artefacts");
    shape.parker_delta = std::max(shape.parker_delta, 0.0);
  }
  return shape;
}

double parker_beta(const ScanShape& shape, double angle) { return wrap(wrap(angle) - shape.start_angle); }

FilterView filter_view(const ScanGeometry& geometry, const ScanShape& shape, std::size_t view) {
  const View& v = geometry.views[view];
  const Detector& d = geometry.detector;
  // The ramp acts on the virtual detector through the isocentre, whose pixel
  // pitch is pitch_u · SID / SDD; the response is for unit spacing, so the
  // convolution's 1/spacing goes into the scale. Full scans see every ray
  // twice and take half of each.
  const double virtual_pitch = d.pitch_u * v.source_to_isocenter / v.source_to_detector;
  const double redundancy = shape.short_scan ? 1.0 : 0.5;
  FilterView f{};
  f.scale = static_cast<float>(shape.angular_gaps[view] * redundancy / virtual_pitch);
  f.sdd = static_cast<float>(v.source_to_detector);
  f.foot_u = static_cast<float>(v.source_offset_u);
  f.foot_v = static_cast<float>(v.source_offset_v);
  f.u_first = static_cast<float>(-0.5 * (d.columns - 1) * d.pitch_u + v.detector_offset_u);
  f.v_first = static_cast<float>(-0.5 * (d.rows - 1) * d.pitch_v + v.detector_offset_v);
  f.pitch_u = static_cast<float>(d.pitch_u);
  f.pitch_v = static_cast<float>(d.pitch_v);
  f.parker_beta = shape.short_scan ? static_cast<float>(parker_beta(shape, v.angle)) : 0.0F;
  f.parker_delta = shape.short_scan ? static_cast<float>(shape.parker_delta) : -1.0F;
  f.parker_sign = 1.0F;
  f.reserved = 0;
  return f;
}

BackprojectView backproject_view(const ScanGeometry& geometry, const VolumeGrid& grid, std::size_t view) {
  const View& v = geometry.views[view];
  const Detector& d = geometry.detector;
  const double cos_a = std::cos(v.angle);
  const double sin_a = std::sin(v.angle);
  const Vec3& o = grid.origin;
  const Vec3& s = grid.voxel_size;
  // a = P·û, b = P_z, c = P·(toward the source), each affine in (i, j, k).
  const Affine a{s[0] * cos_a, s[1] * sin_a, 0.0, o[0] * cos_a + o[1] * sin_a};
  const Affine b{0.0, 0.0, s[2], o[2]};
  const Affine c{s[0] * sin_a, -s[1] * cos_a, 0.0, o[0] * sin_a - o[1] * cos_a};
  const double sid = v.source_to_isocenter;
  const double sdd = v.source_to_detector;
  // w = (SID − c) / SID; magnification = SDD / (SID · w).
  const Affine w = sum(scaled(c, -1.0 / sid), Affine{0.0, 0.0, 0.0, 1.0});
  const double column_bias = (v.source_offset_u - v.detector_offset_u) / d.pitch_u + 0.5 * (d.columns - 1);
  const double row_bias = (v.source_offset_v - v.detector_offset_v) / d.pitch_v + 0.5 * (d.rows - 1);
  const Affine column =
      sum(scaled(w, column_bias), scaled(sum(a, Affine{0, 0, 0, -v.source_offset_u}), sdd / (sid * d.pitch_u)));
  const Affine row =
      sum(scaled(w, row_bias), scaled(sum(b, Affine{0, 0, 0, -v.source_offset_v}), sdd / (sid * d.pitch_v)));
  BackprojectView m{};
  for (int e = 0; e < 4; ++e) {
    m.column[e] = static_cast<float>(column[e]);
    m.row[e] = static_cast<float>(row[e]);
    m.depth[e] = static_cast<float>(w[e]);
  }
  return m;
}

int ramp_log2_length(int columns) {
  int log2n = 4;
  while ((1 << log2n) < 2 * columns) ++log2n;
  return log2n;
}

std::vector<double> ramp_response(int log2n, RampWindow window, double cutoff) {
  if (!(cutoff > 0.0) || cutoff > 1.0) throw std::invalid_argument("ramp filter: cutoff must be in (0, 1]");
  const int n = 1 << log2n;
  // The band-limited ramp sampled at unit spacing (Kak & Slaney, eq. 61):
  // h(0) = 1/4, h(m) = −1/(π m)² for odd m, 0 for even m; its DFT is real.
  std::vector<double> cosine(static_cast<std::size_t>(n));
  for (int m = 0; m < n; ++m) cosine[m] = std::cos(2.0 * M_PI * m / n);
  std::vector<double> response(static_cast<std::size_t>(n));
  for (int k = 0; k <= n / 2; ++k) {
    double value = 0.25;
    for (int m = 1; m < n / 2; m += 2) {
      const double h = -1.0 / (M_PI * M_PI * static_cast<double>(m) * m);
      value += 2.0 * h * cosine[(static_cast<std::int64_t>(k) * m) % n];
    }
    const double frequency = static_cast<double>(k) / (0.5 * n) / cutoff;  // 1 at the cutoff
    double gain = 0.0;
    if (frequency <= 1.0) {
      switch (window) {
        case RampWindow::RamLak:
          gain = 1.0;
          break;
        case RampWindow::SheppLogan:
          gain = frequency == 0.0 ? 1.0 : std::sin(0.5 * M_PI * frequency) / (0.5 * M_PI * frequency);
          break;
        case RampWindow::Cosine:
          gain = std::cos(0.5 * M_PI * frequency);
          break;
        case RampWindow::Hamming:
          gain = 0.54 + 0.46 * std::cos(M_PI * frequency);
          break;
        case RampWindow::Hann:
          gain = 0.5 + 0.5 * std::cos(M_PI * frequency);
          break;
      }
    }
    response[k] = value * gain / n;
    if (k > 0 && k < n / 2) response[n - k] = response[k];
  }
  return response;
}

RowBand rows_for_slab(const ScanGeometry& geometry, const VolumeGrid& grid, std::uint32_t k_begin,
                      std::uint32_t k_end) {
  double lowest = 1e300;
  double highest = -1e300;
  const double i_edges[2] = {-0.5, grid.size[0] - 0.5};
  const double j_edges[2] = {-0.5, grid.size[1] - 0.5};
  const double k_edges[2] = {k_begin - 0.5, k_end - 0.5};
  for (std::size_t view = 0; view < geometry.view_count(); ++view) {
    for (double i : i_edges)
      for (double j : j_edges)
        for (double k : k_edges) {
          const double row = geometry.project(view, grid.voxel_centre(i, j, k)).row;
          lowest = std::min(lowest, row);
          highest = std::max(highest, row);
        }
  }
  const int rows = geometry.detector.rows;
  RowBand band;
  const double first = std::clamp(std::floor(lowest) - 1.0, 0.0, static_cast<double>(rows));
  const double end = std::clamp(std::ceil(highest) + 2.0, 0.0, static_cast<double>(rows));
  // Both ends even: the filter packs rows in pairs (2m, 2m+1), and a row
  // must meet the same partner in every band to come out with the same bits.
  band.first = static_cast<int>(first) & ~1;
  band.end = std::min(rows, (std::max(static_cast<int>(end), band.first) + 1) & ~1);
  return band;
}

}  // namespace ivol::recon::detail
