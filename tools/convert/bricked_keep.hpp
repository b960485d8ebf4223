// A keep rule (--keep) written as a bricked regular grid (--structure
// bricked): the voxels the rule keeps as they are, every other voxel as one
// background value, the mean of the values below the threshold, which codec
// 4 stores once a brick. This is the "object" fidelity of bench/RESULTS.md's
// peers' tables (the part and a margin, one background value elsewhere).
// The default under a keep rule stays the octree, which keeps an average
// per coarse leaf instead (more of the air's values, and a larger file).
#pragma once

#include <cstdint>

#include "ivol_io.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

// What the rule did, for the report and the file's metadata.
struct BrickedKeepOutcome {
  float threshold = 0.0f;
  double background = 0.0;          // the value outside, as stored (what a reader returns there)
  std::uint64_t kept = 0;           // voxels kept as they are
  std::uint64_t replaced = 0;       // voxels that took the background value
  std::uint64_t nans_replaced = 0;  // of them: NaNs (not counted in max_abs_error)
  double max_abs_error = 0.0;       // the largest |value − background| of the others
};

// The bricked grid of `source` under options.keep (which must be set), as
// import_to_ivol writes it for --structure bricked; fills the report.
void import_bricked_keep(SlabReader& source, const std::string& path, const ImportOptions& options,
                         const StreamingOptions& streaming, ImportReport& report);

}  // namespace ivol::convert
