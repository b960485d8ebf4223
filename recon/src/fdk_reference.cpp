#include "ivol/recon/fdk_reference.hpp"

#include <cmath>

#include "fdk_plan.hpp"

namespace ivol::recon {
namespace {

double parker(double beta, double gamma, double delta) {
  if (beta < 0.0) return 0.0;
  if (beta < 2.0 * (delta - gamma)) return std::pow(std::sin(M_PI / 4.0 * beta / (delta - gamma)), 2);
  if (beta < M_PI - 2.0 * gamma) return 1.0;
  if (beta <= M_PI + 2.0 * delta)
    return std::pow(std::sin(M_PI / 4.0 * (M_PI + 2.0 * delta - beta) / (delta + gamma)), 2);
  return 0.0;
}

}  // namespace

std::vector<double> reconstruct_fdk_reference(ProjectionSource& projections, const ScanGeometry& geometry,
                                              const VolumeGrid& grid, RampWindow window, double cutoff) {
  const Detector& d = geometry.detector;
  const detail::ScanShape shape = detail::analyse_scan(geometry);
  const int log2n = detail::ramp_log2_length(d.columns);
  const int n = 1 << log2n;
  const std::vector<double> response = detail::ramp_response(log2n, window, cutoff);
  // The windowed ramp as a convolution kernel: the inverse DFT of its
  // response (which already carries 1/n).
  std::vector<double> kernel(static_cast<std::size_t>(d.columns));
  for (int m = 0; m < d.columns; ++m) {
    double value = 0.0;
    for (int k = 0; k < n; ++k) value += response[k] * std::cos(2.0 * M_PI * static_cast<double>(k) * m / n);
    kernel[m] = value;
  }

  std::vector<double> volume(grid.voxel_count(), 0.0);
  std::vector<float> image(static_cast<std::size_t>(d.columns) * d.rows);
  std::vector<double> weighted(image.size());
  std::vector<double> filtered(image.size());
  for (std::size_t view = 0; view < geometry.view_count(); ++view) {
    const View& v = geometry.views[view];
    projections.read_rows(view, 0, d.rows, image.data());
    const double virtual_pitch = d.pitch_u * v.source_to_isocenter / v.source_to_detector;
    const double scale = shape.angular_gaps[view] * (shape.short_scan ? 1.0 : 0.5) / virtual_pitch;
    for (int r = 0; r < d.rows; ++r)
      for (int c = 0; c < d.columns; ++c) {
        const double u = (c - 0.5 * (d.columns - 1)) * d.pitch_u + v.detector_offset_u - v.source_offset_u;
        const double w = (r - 0.5 * (d.rows - 1)) * d.pitch_v + v.detector_offset_v - v.source_offset_v;
        const double sdd = v.source_to_detector;
        double weight = scale * sdd / std::sqrt(sdd * sdd + u * u + w * w);
        if (shape.short_scan)
          weight *= parker(detail::parker_beta(shape, v.angle), -std::atan(u / sdd), shape.parker_delta);
        weighted[static_cast<std::size_t>(r) * d.columns + c] =
            weight * image[static_cast<std::size_t>(r) * d.columns + c];
      }
    for (int r = 0; r < d.rows; ++r)
      for (int c = 0; c < d.columns; ++c) {
        double sum = 0.0;
        for (int j = 0; j < d.columns; ++j)
          sum +=
              weighted[static_cast<std::size_t>(r) * d.columns + j] * kernel[static_cast<std::size_t>(std::abs(c - j))];
        filtered[static_cast<std::size_t>(r) * d.columns + c] = sum;
      }
    auto pixel = [&](long c, long r) {
      if (c < 0 || r < 0 || c >= d.columns || r >= d.rows) return 0.0;
      return filtered[static_cast<std::size_t>(r) * d.columns + static_cast<std::size_t>(c)];
    };
    std::size_t index = 0;
    for (std::uint32_t k = 0; k < grid.size[2]; ++k)
      for (std::uint32_t j = 0; j < grid.size[1]; ++j)
        for (std::uint32_t i = 0; i < grid.size[0]; ++i, ++index) {
          const ScanGeometry::Projected p = geometry.project(view, grid.voxel_centre(i, j, k));
          const double c0 = std::floor(p.column);
          const double r0 = std::floor(p.row);
          const double fc = p.column - c0;
          const double fr = p.row - r0;
          const long ci = static_cast<long>(c0);
          const long ri = static_cast<long>(r0);
          const double value = (1 - fr) * ((1 - fc) * pixel(ci, ri) + fc * pixel(ci + 1, ri)) +
                               fr * ((1 - fc) * pixel(ci, ri + 1) + fc * pixel(ci + 1, ri + 1));
          // FDK's distance weight (SID / (SID − depth))², from the magnification.
          const double distance_weight = p.magnification * v.source_to_isocenter / v.source_to_detector;
          volume[index] += distance_weight * distance_weight * value;
        }
  }
  return volume;
}

}  // namespace ivol::recon
