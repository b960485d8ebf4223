// The paper's rule for where to keep full resolution: voxels above a threshold
// (the object), grown by a safety margin.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol {

// 1 where the voxel lies within `margin` voxels (Chebyshev distance) of a voxel
// whose value exceeds `threshold`, else 0.
std::vector<std::uint8_t> threshold_keep_mask(const float* data, const Dims& dims, float threshold, unsigned margin);

// Otsu's threshold over a histogram of the values (ignores NaN).
float otsu_threshold(const float* data, std::uint64_t count, unsigned bins = 256);
// The same from a histogram of `histogram.size()` equal bins over [lo, hi],
// for volumes read in parts.
float otsu_threshold_from_histogram(const std::vector<double>& histogram, double lo, double hi);
// Adds `data` (NaN ignored) to a histogram of `histogram.size()` equal bins
// over [lo, hi], lo < hi the smallest and largest of all the values: the
// binning otsu_threshold uses, so that values added in parts, once their
// range is known, give its threshold exactly.
void add_to_otsu_histogram(const float* data, std::uint64_t count, float lo, float hi, std::vector<double>& histogram);

}  // namespace ivol
