// The paper's first step (Betz et al., section 4): a quick low-resolution
// reconstruction that finds the object, before the structure is generated.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol/structures.hpp"

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

// The detection rule's settings (docs/refinement.md; the share and the
// thinning measured in bench/RESULTS.md, "Refinement rule").
struct DetectionRule {
  unsigned factor = 2;      // a cell's edge in voxels (a power of two)
  unsigned thinning = 2;    // samples from every 2nd view, 2×2 pixels merged
  unsigned margin = 2;      // voxels around a cell whose samples count for it
  double otsu_share = 0.3;  // the threshold: this share of the samples' Otsu's threshold
};

// A preview built to find the object rather than to show it (the refinement
// rule of docs/refinement.md): the volume is reconstructed at 1/(factor/2)
// (two samples per cell and axis; at 1/2, one, when factor is 2) from every
// `thinning`-th view with thinning² pixels merged; each cell of factor³ full
// voxels then takes the LARGEST sample within `margin_voxels` of it (rounded
// up to whole samples), not its centre's value nor a mean. A full voxel lies
// within half a sample spacing of a sample of its cell, so a wall or wire one
// voxel thin shows in its cell near its own density instead of blurring into
// air, and the margin catches the dense reconstruction's own blur across a
// cell's face without adding whole cells. Samples arrive slice by slice and
// are pooled at once: host memory is the cells pooled along x and y plus one
// sample in eight. otsu_threshold is Otsu's over that one in eight (not over
// the maxima, which would bias it). Each cell's largest sample is then
// rounded up to binary16 (float_to_binary16_upward): never below the float,
// so no cell the float would keep is dropped, and the cells waiting for
// Otsu's threshold take half the bytes (issue 23). factor: a power of two,
// at least 2.
Preview reconstruct_detection_preview(ProjectionSource& projections, const ScanGeometry& geometry,
                                      const FdkOptions& options, const VolumeGrid& full, unsigned factor,
                                      unsigned thinning, unsigned margin_voxels);

// The detection rule's need mask without the whole preview (issue 23): the
// same samples as reconstruct_detection_preview, pooled along z as soon as a
// cell layer's samples have arrived (a ring of 1 + ratio + 2·reach layers
// pooled along x and y). Held whatever the budget: that ring, a few slices'
// buffers and the need mask at 1 bit per cell (NeedMask::bits); the rest of
// `preview_memory` holds, first come first held, the finished layers of
// cells and the samples for Otsu's threshold (one in eight), and what does
// not fit goes to unlinked temporary files in `temp_directory` (TMPDIR, else
// /tmp, when empty), each record compressed (byte planes, zstd) where that
// makes it smaller; cells wait as binary16, rounded up. Otsu's threshold
// needs every sample first, so it is
// found after the reconstruction: the samples' range is tracked as they
// arrive and a 256-bin histogram over it is added to record by record
// (add_to_otsu_histogram, the binning of otsu_threshold), so the threshold
// is exactly reconstruct_detection_preview's. Then each layer of cells is
// thresholded into the mask, which is need_mask_from_low_resolution(preview,
// ..., margin 0)'s, cell for cell. Distributed, rank 0 reconstructs and
// broadcasts Otsu's threshold and then each layer of cells. A budget below
// detection_fixed_bytes is refused (Error LimitExceeded) before any work.
struct DetectionMaskOptions {
  DetectionRule rule;
  unsigned margin_voxels = 2;                             // as reconstruct_detection_preview's
  std::optional<float> threshold;                         // given; else rule.otsu_share × Otsu's
  std::uint64_t preview_memory = std::uint64_t{1} << 30;  // bytes held, the need mask's included
  std::string temp_directory;
};

struct DetectionMask {
  NeedMask mask;
  VolumeGrid grid;              // the cells' grid (the preview's)
  float otsu_threshold = 0.0F;  // of the samples, before the share
  float threshold = 0.0F;       // applied
  double seconds = 0.0;
  std::uint64_t peak_preview_bytes = 0;  // held at once: ring, cell layers, Otsu's samples, the need mask
  std::uint64_t spilled_bytes = 0;       // cell layers and Otsu's samples written to temporary files
  std::uint64_t spilled_raw_bytes = 0;   // the same records before compression
};

// What detect_need_mask holds whatever its budget (the ring, the slice
// buffers, the packed need mask), in bytes.
std::uint64_t detection_fixed_bytes(const VolumeGrid& full, const DetectionMaskOptions& detection);
// The most bytes detect_need_mask can write to temporary files: the cell
// layers and Otsu's samples beyond its budget, and the thinned scan's
// filtered rows beyond options.filtered_rows_memory_limit
// (filtered_rows_disk_bound). For the disk check before a run.
std::uint64_t detection_temp_bytes(const ScanGeometry& geometry, const FdkOptions& options, const VolumeGrid& full,
                                   const DetectionMaskOptions& detection);

DetectionMask detect_need_mask(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                               const VolumeGrid& full, const DetectionMaskOptions& detection);

}  // namespace ivol::recon
