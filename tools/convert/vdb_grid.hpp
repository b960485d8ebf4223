// The part of read_vdb that is ivol's own: a FloatGrid already in memory to
// the dense volume, its active and tile flags, geometry and metadata. Split
// from the file reading (libopenvdb's parser, run in a child process by the
// converters) so that the fuzz harness tests/fuzz/fuzz_vdb_grid.cpp can build
// hostile grids directly, thousands a second, instead of going through
// libopenvdb's file reader at a few dozen a second.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>

#include "vdb_io.hpp"

namespace ivol::convert {

// As read_vdb (vdb_io.hpp) from the point the grid is read; `context` names
// the file and grid in messages. Throws ivol::Error: InvalidArgument (no
// active voxel; a transform that is not an axis-aligned linear one),
// LimitExceeded (the active voxels span more than 2^32 - 1 along an axis, or
// held densely at 6 bytes a voxel they exceed `memory_bytes`, 0:
// kDefaultMemoryBytes).
VdbVolume volume_from_grid(const openvdb::FloatGrid& grid, const std::string& context, std::uint64_t memory_bytes);

}  // namespace ivol::convert
