// Whether the disks a run writes to have the room it will need, checked
// before any work: an .ivol file and, for an octree, the writer's spill file
// (ivol/streaming_writer.hpp), each estimated from the volume's size.
//
// The estimate rule: the file takes about the values uncompressed, voxels x
// 2 bytes for the 16-bit encodings (binary16, uint16) and x 4 for float32 -
// what a lossless file of noisy values approaches (0.5 to 0.75 of it
// measured, bench/RESULTS.md); smooth or coarsened (--keep) volumes take
// far less, so the rule errs on the side of refusing. An octree's spill file
// holds the octree compressed as the file's blocks are, about the file's
// size again, in the spill directory, and both exist at once at the end. On
// one filesystem the needs add up; the output's temporary file takes the
// file's room until it is renamed into place.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ivol/encoding.hpp"
#include "ivol/geometry.hpp"

namespace ivol::convert {

struct DiskNeed {
  std::string directory;  // where the file goes
  std::uint64_t bytes = 0;
  std::string what;  // "the output x.ivol", "the octree writer's spill file"
  bool temporary = false;  // gone when the run ends; --temp-dir chooses its disk
};

// What writing a volume of `dims` into `output` needs, by the rule above;
// `octree`: the streaming octree writer (a spill file in temp_directory, or
// where spill_directory_for puts it).
std::vector<DiskNeed> ivol_disk_needs(const Dims& dims, ValueEncoding encoding, bool octree, const std::string& output,
                                      const std::string& temp_directory);

// Throws Error(LimitExceeded) for the first filesystem whose available bytes
// (statvfs f_bavail, as an unprivileged writer gets them) are fewer than its
// needs add up to, naming its directory, the bytes needed (and for what) and
// the bytes available. IVOL_TEST_FREE_BYTES, when set, stands for every
// filesystem's available bytes (for tests).
void require_disk_space(const std::vector<DiskNeed>& needs);

}  // namespace ivol::convert
