// FDK in double precision on the CPU, written from the formulas rather than
// from the OpenCL path: the rays are found with ScanGeometry::project, the
// ramp filter is a direct convolution, nothing is batched or cut into slabs.
// Slow; it exists so that tests can hold the device path to float round-off.
#pragma once

#include <vector>

#include "ivol/recon/fdk.hpp"

namespace ivol::recon {

std::vector<double> reconstruct_fdk_reference(ProjectionSource& projections, const ScanGeometry& geometry,
                                              const VolumeGrid& grid, RampWindow window = RampWindow::RamLak,
                                              double cutoff = 1.0);

}  // namespace ivol::recon
