// Host-side arithmetic of FDK, in double: which views a scan has and how much
// angle each covers, the per-view weights and projection matrices handed to
// the kernels, the ramp filter's response, and the detector rows a slab of
// the volume needs.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/geometry.hpp"
#include "recon_layout.h"

namespace ivol::recon::detail {

struct ScanShape {
  bool short_scan = false;
  double start_angle = 0.0;          // short scans: the first view's angle
  double parker_delta = -1.0;        // short scans: (arc − π) / 2
  double arc = 0.0;                  // angle covered from the first view to the last, rad
  double fan_half_angle = 0.0;       // the widest ray's angle to the central ray, rad
  std::vector<double> angular_gaps;  // per view, the angle it stands for, rad
  std::vector<std::string> warnings;
};

// Full or short scan, from the largest gap between successive angles.
ScanShape analyse_scan(const ScanGeometry& geometry);

// Angle of view `view` from the start of a short scan, in [0, 2π).
double parker_beta(const ScanShape& shape, double angle);

FilterView filter_view(const ScanGeometry& geometry, const ScanShape& shape, std::size_t view);
BackprojectView backproject_view(const ScanGeometry& geometry, const VolumeGrid& grid, std::size_t view);

// Length of the zero-padded rows: the power of two ≥ 2·columns.
int ramp_log2_length(int columns);
// The real, even response of the windowed ramp at the n = 2^log2n DFT
// frequencies, for unit detector spacing (the per-view scale carries the
// pitch), including the inverse transform's 1/n.
std::vector<double> ramp_response(int log2n, RampWindow window, double cutoff);

struct RowBand {
  int first = 0;  // even, so that the filter's row pairs are the detector's
  int end = 0;    // even too, unless it is the detector's last row
  int rows() const { return end - first; }
};
// Detector rows that voxels of slices [k_begin, k_end) project onto in any
// view, with the margin bilinear interpolation needs.
RowBand rows_for_slab(const ScanGeometry& geometry, const VolumeGrid& grid, std::uint32_t k_begin, std::uint32_t k_end);

}  // namespace ivol::recon::detail
