// OpenVDB import and export of dense volumes (float grids only).
//
// Index space and the dense array: OpenVDB puts voxel centres at integer
// index coordinates (i, j, k). read_vdb takes the grid's active voxel
// bounding box [min, max] (active tiles included, evalActiveVoxelBoundingBox)
// and maps index (i, j, k) to dense voxel (i - min.x, j - min.y, k - min.z),
// x fastest, so that dims = max - min + 1. Geometry comes from the grid's
// transform, which must be linear and axis-aligned (a scale and a
// translation, no rotation, shear or mirroring; a frustum is refused):
// voxel_size is the scale along each axis and origin the world position of
// the centre of index min. write_vdb does the reverse with min = (0, 0, 0).
// Grid metadata (strings), both ways: "unit" (length unit of the transform;
// written only with has_geometry), "quantity", "value_unit" and
// "provenance" (ivol's provenance JSON; "voxel_size_known": false there
// makes the transform meaningless: has_geometry false).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "dense_volume.hpp"
#include "exactness.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

struct VdbVolume {
  // Float32 samples over the active bounding box; voxels outside the active
  // set hold whatever the grid holds there (usually the background).
  DenseVolume volume;
  std::vector<std::uint8_t> active;     // 1 where the grid's voxel is active, per dense voxel
  std::vector<std::uint8_t> from_tile;  // 1 where that active value comes from a tile, not a leaf voxel
  float background = 0.0f;
  std::string grid_name;
  bool was_half = false;  // the file stored the values as 16-bit floats (saveFloatAsHalf)
};

// Reads the float grid `grid_name`, or when empty the first float grid in
// the order OpenVDB's io::File lists grids: by name, as vdb_print shows them,
// not the order they were written in.
// Throws ivol::Error: Io (cannot open), Malformed (not a VDB file, unreadable
// grid), InvalidArgument (no such grid or no float grid: the message lists
// the grids and their types; a grid that is not float; a transform that is
// not an axis-aligned linear one; a grid with no active voxel), LimitExceeded
// (the active voxels span more than 2^32 - 1 along an axis, or their
// bounding box, held densely at 6 bytes a voxel, exceeds `memory_bytes`;
// 0: kDefaultMemoryBytes of sizes.hpp).
VdbVolume read_vdb(const std::string& path, const std::string& grid_name = "", std::uint64_t memory_bytes = 0);

// What open_vdb_slabs tells besides the shape: the grid read, its background,
// whether its values were stored as 16-bit floats. The per-voxel active and
// tile flags of VdbVolume stay in the child: the converters do not use them,
// and they would double what crosses the socket.
struct VdbSourceInfo {
  std::string grid_name;
  float background = 0.0f;
  bool was_half = false;
};

// read_vdb's volume, slab by slab, for the converters. libopenvdb runs in a
// child process of its own (isolated_worker.hpp, worker kind "vdb-volume"):
// libopenvdb allocates what a damaged file's block headers claim (64 GiB,
// 1 TiB) and may crash on one, so a crash is ivol::Error(Malformed) naming
// the file, and an allocation beyond the child's limit is
// ivol::Error(LimitExceeded), never the parent's memory. The child reads the
// grid whole (as read_vdb does: the dense box within `memory_bytes`, 0:
// kDefaultMemoryBytes) and holds the grid beside its dense copy, so it may
// allocate twice that budget; this process holds one slab at a time.
std::unique_ptr<SlabReader> open_vdb_slabs(const std::string& path, const std::string& grid_name = "",
                                           VdbSourceInfo* source = nullptr, std::uint64_t memory_bytes = 0);
// The same in this process, as the child runs it; for the fuzz harness,
// which must see the library's crashes to tell them from ivol's.
std::unique_ptr<SlabReader> open_vdb_slabs_in_process(const std::string& path, const std::string& grid_name = "",
                                                      VdbSourceInfo* source = nullptr, std::uint64_t memory_bytes = 0);

// Writes a FloatGrid named grid_name: the voxels whose value differs from
// `background` become active (tolerance 0), uniform 8^3 blocks become tiles
// (tools::prune), values stored as 16-bit floats when `half` (saveFloatAsHalf:
// values round to binary16, out-of-range ones become infinite). The transform
// maps index (x, y, z) to origin + (x, y, z) * voxel_size (identity without
// geometry). Grid metadata: class fog volume when the background is 0 and
// every value lies in [0, 1] (OpenVDB's convention), else unknown; "unit".
// Written to a temporary file in the same directory, then renamed.
// Voxels equal to the background but of other bits (-0 against +0) are made
// active so that they keep their bits. Before anything is written, the grid
// is compared with the volume bit for bit (and with `half`, every value with
// its binary16 rounding): `check`, when given, sees what would change and
// throws to refuse; the result says the same.
// What write_vdb holds at its peak for a volume of `dims` given as float32:
// the volume itself and the tree copyFromDense builds before pruning, every
// 8^3 block a leaf (a volume without a voxel at the background), 4.3 bytes
// a voxel besides the volume's 4. Other sample types are converted to a
// float32 copy first, 4 bytes a voxel more.
double vdb_output_bytes(const Dims& dims);

LossTally write_vdb(const DenseVolume& volume, const std::string& path, float background,
                    const std::string& grid_name = "density", bool half = true,
                    const std::function<void(const LossTally&)>& check = {});

}  // namespace ivol::convert
