// The paper's four ways to hold a volume with inhomogeneous resolution
// (Betz et al., sections 3-4), behind one interface: the regular grid, the
// rectilinear grid (per-axis borders), the nested grid (a coarse grid whose
// cells hold their own regular sub-grids) and the octree.
//
// Every structure is a list of bricks: regular sub-grids of voxels of one
// size. A reconstruction kernel walks a brick as it walks a dense volume
// (origin, voxel size, counts), and the values of all bricks lie in one
// array, brick after brick, x fastest within a brick. Coordinates are in
// full-resolution voxels: voxel (x, y, z) of the full grid covers
// [x, x + 1) x [y, y + 1) x [z, z + 1).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/brick_list.hpp"
#include "ivol/geometry.hpp"
#include "ivol/octree.hpp"
#include "ivol/streaming_writer.hpp"

namespace ivol {

const char* structure_name(StructureKind kind);  // "regular", "rectilinear", "nested", "octree"
bool parse_structure(const std::string& name, StructureKind& out);

// Bytes the structure needs as the paper stores it: 16-bit values and the
// structure's own bookkeeping (borders, cell pointers, node words).
struct StructureMemory {
  std::uint64_t value_bytes = 0;
  std::uint64_t structure_bytes = 0;
  std::uint64_t total() const { return value_bytes + structure_bytes; }
};

class VoxelStructure {
 public:
  virtual ~VoxelStructure() = default;
  virtual StructureKind kind() const = 0;
  // Exact bytes as the paper stores the structure (16-bit values).
  virtual StructureMemory memory() const = 0;

  const Dims& dims() const { return dims_; }
  const BrickList& bricks() const { return bricks_; }
  std::uint64_t voxel_count() const { return voxel_total_; }  // values to compute
  // The values, brick after brick (working precision; the format stores 16
  // bits), zero at first. The array is allocated by the first non-const call,
  // not by generation: it is the reconstruction's storage, not the structure's.
  std::vector<float>& values();
  const std::vector<float>& values() const;

  // Each full-resolution voxel takes the value of the structure's voxel that
  // covers it. `out` is [z][y][x].
  void to_dense(float* out) const;
  // Each structure voxel takes the mean of the full-resolution voxels it covers.
  void sample_dense(const float* dense);
  // The brick voxel index covering full-resolution voxel (x, y, z).
  std::uint64_t value_index(std::uint32_t x, std::uint32_t y, std::uint32_t z) const;

 protected:
  void finish_bricks();  // assigns first_value and counts the voxels
  Dims dims_{};
  BrickList bricks_;  // made with dims_ by each structure's constructor
  std::uint64_t voxel_total_ = 0;

 public:
  // The rectilinear grid's border positions along x, y, z (spec §8A.2); empty
  // for the other kinds.
  const std::array<std::vector<std::uint32_t>, 3>& borders() const { return borders_; }
  // The nested grid's cell edge (a power of two); 0 for the other kinds.
  std::uint32_t nested_cell() const { return nested_cell_; }

 protected:
  std::array<std::vector<std::uint32_t>, 3> borders_;
  std::uint32_t nested_cell_ = 0;

 private:
  void build_lookup() const;
  mutable std::vector<float> values_;
  // For value_index, built on first use: the bricks meeting each 16^3 tile
  // (CSR: tile_start_, owner_).
  mutable std::vector<std::uint32_t> tile_start_;
  mutable std::vector<std::uint32_t> owner_;
};

// Where full resolution is needed, as the structures are generated from it: a
// mask over a low-resolution grid whose cells are `factor` full-resolution
// voxels wide (factor a power of two; 1 = full resolution).
struct NeedMask {
  Dims dims{};                     // full-resolution dimensions of the volume
  std::uint32_t factor = 1;        // full-resolution voxels per mask cell, per axis
  Dims cells{};                    // ceil(dims / factor)
  std::vector<std::uint8_t> need;  // 1 where the cell needs full resolution, [z][y][x]
  // Or the same cells one bit each (cell n is bit n % 64 of word n / 64),
  // with `need` empty: an eighth of the memory, for masks of large volumes
  // (recon::detect_need_mask). at() reads either form.
  std::vector<std::uint64_t> bits;
  bool packed() const { return !bits.empty(); }
  bool at(std::uint64_t n) const { return packed() ? ((bits[n >> 6] >> (n & 63)) & 1U) != 0 : need[n] != 0; }
  bool at(std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return at((std::uint64_t{k} * cells[1] + j) * cells[0] + i);
  }
  std::uint64_t memory_bytes() const { return need.size() + bits.size() * sizeof(std::uint64_t); }
};

// The paper's rule on a low-resolution reconstruction: cells above
// `threshold` (the object), grown by `margin_voxels` full-resolution voxels
// (rounded up to whole cells). Uses all cores.
NeedMask need_mask_from_low_resolution(const float* low, const Dims& low_dims, std::uint32_t factor,
                                       const Dims& full_dims, float threshold, unsigned margin_voxels);

struct GenerationOptions {
  // Rectilinear: the largest interval outside the needed ranges, in voxels.
  std::uint32_t rectilinear_max_interval = 64;
  // Nested: the coarse cell's edge in full-resolution voxels (a power of two).
  std::uint32_t nested_cell = 16;
  unsigned threads = 0;  // 0: all hardware threads
};

// Builds a structure from a need mask: full resolution wherever a cell needs
// it, coarse elsewhere as the structure allows. Values start at zero.
std::unique_ptr<VoxelStructure> generate_structure(StructureKind kind, const NeedMask& mask,
                                                   const GenerationOptions& options = {});

// Slices first .. end - 1 of a volume.
struct SliceRange {
  std::uint32_t first = 0;
  std::uint32_t end = 0;
};

// The bricks of `structure` that meet any of `ranges` (increasing and
// disjoint), as a structure of the same kind with values of its own,
// numbered anew: to reconstruct and build part of a structure, as a rank of a
// distributed run does with its slabs (docs/distributed.md). A brick of fine
// voxels is cut to the slices of each range it meets; a brick of coarse
// voxels is in the part whole, once, even where it reaches beyond a range or
// meets several. The structure's bricks must be ordered by their first slice,
// as generate_structure orders them; the part's are too.
std::unique_ptr<VoxelStructure> structure_part(const VoxelStructure& structure, const std::vector<SliceRange>& ranges);

// Writes a structure as an .ivol file of its own kind: the octree through
// StreamingOctreeWriter, slab by slab (full resolution exactly where it has
// fine voxels, each coarse voxel one leaf); the regular, rectilinear and
// nested grids in their form of spec §8A. `options.build` gives the value
// encoding (and scale and offset); the values must exist.
StreamingResult write_structure(const VoxelStructure& structure, const std::string& path, const Metadata& metadata,
                                StreamingOptions options = {});

}  // namespace ivol
