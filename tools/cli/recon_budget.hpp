// The budget of one `ivol recon` run (issue 23): how much host memory it
// may use when --memory is not given, and the temporary disk it will need,
// checked before any work.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "disk_space.hpp"
#include "ivol/encoding.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/preview.hpp"

namespace ivol::cli {

struct MemoryBudget {
  std::uint64_t bytes = 0;
  std::string rule;  // how it was chosen, for the notes and --json
};

// --memory when given (MiB, given_mib > 0); else half of the memory the
// process may use: its memory cgroup's limit when one is set (cgroup v1
// memory.limit_in_bytes or v2 memory.max, the tightest of its cgroup and
// the cgroups above it), else MemAvailable of /proc/meminfo; clamped to
// [256 MiB, 1 TiB]. IVOL_TEST_ROOT, when set, is prefixed to /proc and /sys
// paths (for tests).
MemoryBudget memory_budget(std::uint64_t given_mib);

// The temporary disk a reconstruction needs, by phase (the detection
// preview's files are gone before the reconstruction's are made), each a
// list of needs whose sizes add up per filesystem (convert/disk_space.hpp).
struct ReconDiskNeeds {
  std::vector<convert::DiskNeed> preview;         // its cells, Otsu's samples and thinned filtered rows
  std::vector<convert::DiskNeed> reconstruction;  // the output, the writer's spill, the filtered rows
};

// `fdk`: the run's options (temp_directory where the filtered rows and the
// preview's files go, filtered_rows_memory_limit); `detection`: the
// detection preview's, when the run makes one; the writer's spill goes to
// spill_directory_for(output, writer_temp_directory). Each estimate is
// the most that part can write (the output and the spill by the rule of
// disk_space.hpp).
ReconDiskNeeds recon_disk_needs(const recon::ScanGeometry& geometry, const recon::VolumeGrid& grid,
                                const recon::FdkOptions& fdk,
                                const std::optional<recon::DetectionMaskOptions>& detection, ValueEncoding encoding,
                                bool octree_spill, const std::string& output, const std::string& writer_temp_directory);

}  // namespace ivol::cli
