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

// A full octree of 64^3 float32 voxels (every voxel a leaf, each value its
// index in the values stream), in small blocks. With `shared_from` (8 ..
// 15), level-4 nodes shared_from .. 15 (the second subtree of level 3) each
// name the level-5 children of the node before them: every node word passes
// its own checks, only the breadth-first numbering (spec §8.3) is broken.
// From 8, each subtree of level 3 is numbered consistently within itself
// and the break lies between two of them; from 9, within one. 0: a valid
// file.
void write_full_octree(const std::string& path, unsigned shared_from);

}  // namespace ivol::test::hostile
