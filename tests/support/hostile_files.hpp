// Hostile .ivol files (issue 17): a few hundred bytes to a few hundred KB on
// disk, every CRC the reader checks before the hostile part valid, each
// aiming at one way a reader could crash, hang or allocate gigabytes. Made
// byte by byte here, not by libformat's writer, which refuses to write them.
// Shared by test_hostile and make_hostile_files (tests/cli/run_hostile.sh).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace ivol::test::hostile {

struct HostileFile {
  std::string name;  // file name without .ivol
  std::string what;  // what it does to a reader
  // Whether a reader must refuse it (exit 2); otherwise it is a valid file
  // that a reader must read within bounded memory.
  bool refused = true;
  bool sparse = false;  // written with a hole: gigabytes apparent, KB on disk
};

// Every hostile file, in a fixed order.
std::vector<HostileFile> catalogue();

// Writes hostile file `name` to `path`; throws std::invalid_argument for an
// unknown name.
void write(const std::string& name, const std::string& path);

// Metadata JSON with `depth` objects or arrays nested in "user" (an
// object): it nests depth + 2 deep (spec §11 counts the top-level object).
std::string deep_metadata(std::size_t depth, bool arrays);
// A valid 1x1x1 float32 octree file with this metadata text.
void write_one_voxel(const std::string& metadata, const std::string& path);

}  // namespace ivol::test::hostile
