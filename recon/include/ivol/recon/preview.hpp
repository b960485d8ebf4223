// The paper's first step (Betz et al., section 4): a quick low-resolution
// reconstruction that finds the object, before the structure is generated.
#pragma once

#include <vector>

#include "ivol/recon/fdk.hpp"

namespace ivol::recon {

struct Preview {
  VolumeGrid grid;            // `factor` times coarser than the full grid
  std::vector<float> values;  // x fastest
  float otsu_threshold = 0.0F;
  double seconds = 0.0;
};

// Reconstructs `full` at 1/factor resolution (factor a power of two): each
// preview voxel covers factor³ full voxels, centred on them. The scan is
// thinned to match: every (factor/2)-th view, detector pixels merged
// (factor/2)², so the preview costs a small fraction of the full
// reconstruction, filtering included.
Preview reconstruct_preview(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                            const VolumeGrid& full, unsigned factor);

}  // namespace ivol::recon
