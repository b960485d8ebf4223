#include "ivol/keep_mask.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

#include "thread_parts.hpp"

namespace ivol {
namespace {

// Grows the set of ones by `radius` along one axis: out[i] = max over
// [i - radius, i + radius], with a running count so the cost does not depend
// on the radius.
void dilate_axis(std::vector<std::uint8_t>& mask, const Dims& dims, int axis, unsigned radius) {
  const std::uint64_t stride = axis == 0 ? 1 : axis == 1 ? dims[0] : std::uint64_t{dims[0]} * dims[1];
  const std::uint64_t n = dims[axis];
  const std::uint64_t lines = voxel_count(dims) / n;
  // Lines are independent: split them over the cores.
  const unsigned threads =
      std::max(1u, std::min<unsigned>(std::thread::hardware_concurrency(), static_cast<unsigned>(lines / 64 + 1)));
  auto work = [&](std::uint64_t first, std::uint64_t last) {
    std::vector<std::uint8_t> line(n);
    for (std::uint64_t li = first; li < last; ++li) {
      // Index of the first voxel of line li.
      std::uint64_t base;
      if (axis == 0)
        base = li * n;
      else if (axis == 1)
        base = (li / dims[0]) * dims[0] * dims[1] + li % dims[0];
      else
        base = li;
      for (std::uint64_t t = 0; t < n; ++t) line[t] = mask[base + t * stride];
      std::uint64_t count = 0;  // ones in the window [t - radius, t + radius]
      for (std::uint64_t t = 0; t < std::min<std::uint64_t>(n, radius); ++t) count += line[t];
      for (std::uint64_t t = 0; t < n; ++t) {
        if (t + radius < n) count += line[t + radius];
        if (t > radius) count -= line[t - radius - 1];
        mask[base + t * stride] = count ? 1 : 0;
      }
    }
  };
  detail::run_parts(threads, [&](unsigned t) { work(lines * t / threads, lines * (t + 1) / threads); });
}

}  // namespace

std::vector<std::uint8_t> threshold_keep_mask(const float* data, const Dims& dims, float threshold, unsigned margin) {
  const std::uint64_t n = voxel_count(dims);
  std::vector<std::uint8_t> mask(n);
  for (std::uint64_t i = 0; i < n; ++i) mask[i] = data[i] > threshold ? 1 : 0;
  if (margin > 0)
    for (int axis = 0; axis < 3; ++axis) dilate_axis(mask, dims, axis, margin);
  return mask;
}

float otsu_threshold_from_histogram(const std::vector<double>& histogram, double lo, double hi) {
  const auto bins = static_cast<unsigned>(histogram.size());
  if (bins < 2 || !(hi > lo)) return static_cast<float>(lo);
  double total = 0.0;
  double total_moment = 0.0;
  for (unsigned b = 0; b < bins; ++b) total += histogram[b], total_moment += b * histogram[b];
  double below = 0.0;
  double below_moment = 0.0;
  double best = -1.0;
  unsigned best_bin = 0;
  for (unsigned b = 0; b + 1 < bins; ++b) {
    below += histogram[b];
    below_moment += b * histogram[b];
    const double above = total - below;
    if (below == 0.0 || above == 0.0) continue;
    const double mean_below = below_moment / below;
    const double mean_above = (total_moment - below_moment) / above;
    const double between = below * above * (mean_below - mean_above) * (mean_below - mean_above);
    if (between > best) best = between, best_bin = b;
  }
  return static_cast<float>(lo + (best_bin + 1) * (hi - lo) / bins);
}

float otsu_threshold(const float* data, std::uint64_t count, unsigned bins) {
  float lo = INFINITY;
  float hi = -INFINITY;
  for (std::uint64_t i = 0; i < count; ++i)
    if (!std::isnan(data[i])) lo = std::min(lo, data[i]), hi = std::max(hi, data[i]);
  if (!(hi > lo)) return lo;
  std::vector<double> histogram(bins, 0.0);
  add_to_otsu_histogram(data, count, lo, hi, histogram);
  return otsu_threshold_from_histogram(histogram, lo, hi);
}

void add_to_otsu_histogram(const float* data, std::uint64_t count, float lo, float hi, std::vector<double>& histogram) {
  const std::uint64_t bins = histogram.size();
  const double scale = static_cast<double>(bins) / (static_cast<double>(hi) - lo);
  for (std::uint64_t i = 0; i < count; ++i) {
    if (std::isnan(data[i])) continue;
    const auto b = std::min<std::uint64_t>(bins - 1, static_cast<std::uint64_t>((data[i] - lo) * scale));
    histogram[b] += 1.0;
  }
}

}  // namespace ivol
