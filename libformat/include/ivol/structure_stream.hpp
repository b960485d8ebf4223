// Writing a structure while it is being reconstructed, without ever holding
// all of its values: a producer (the FDK) fills a StructureValueWindow as
// its slabs finish, and a StructureStreamWriter writes every part of the file
// whose voxels are final, then lets the window forget them.
//
// The contract between them is one number, z_complete: every voxel of the
// structure whose first slice lies below z_complete has its final value.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "ivol/structures.hpp"

namespace ivol {

// Where a writer reads a structure's values from. `brick` is the index of the
// brick holding value `index` (an index into the structure's values).
class StructureValueSource {
 public:
  virtual ~StructureValueSource() = default;
  virtual float value(std::uint32_t brick, std::uint64_t index) const = 0;
  // Every voxel ending at or below slice z has been written: forget it.
  virtual void release_below(std::uint32_t z) = 0;
};

// The values of a structure that are in flight. Values live in pages of
// consecutive value indices (bricks are ordered by their first slice, so a
// page covers a thin range of z), except those of tall lone voxels (a brick
// of one voxel more than kTallVoxel slices tall, as the octree's large
// leaves are): each of those lives on its own, so that a leaf 128 slices
// tall does not keep a page of other voxels alive. Memory: the values of the
// voxels that meet the slices between the writer's position and the
// producer's, rounded up to whole pages at both ends (a page's voxels span
// at most kTallVoxel slices more), plus ~40 bytes per tall voxel held. Not
// thread-safe: one thread fills and reads it.
class StructureValueWindow final : public StructureValueSource {
 public:
  // keep_all: never forget anything (to copy all values out at the end).
  explicit StructureValueWindow(const VoxelStructure& structure, bool keep_all = false);
  ~StructureValueWindow() override;

  // The slot of value `index` of brick `brick`, zero until first written.
  // Throws std::logic_error if that value was already released.
  float& at(std::uint32_t brick, std::uint64_t index);
  float value(std::uint32_t brick, std::uint64_t index) const override;
  void release_below(std::uint32_t z) override;

  std::uint64_t held_bytes() const { return held_bytes_; }
  std::uint64_t peak_bytes() const { return peak_bytes_; }

  static constexpr std::uint64_t kPageValues = 16384;
  static constexpr std::uint32_t kTallVoxel = 16;

 private:
  bool tall(std::uint32_t brick) const;  // a tall lone voxel, kept outside the pages
  void note_held(std::int64_t bytes);

  const VoxelStructure& structure_;
  bool keep_all_;
  std::vector<std::unique_ptr<float[]>> pages_;
  std::vector<std::uint32_t> page_end_;  // last slice (exclusive) any value of the page covers
  std::vector<std::uint8_t> released_;   // 1 once a page has been freed
  std::vector<std::uint32_t> live_pages_;
  std::unordered_map<std::uint64_t, float> tall_values_;
  std::vector<std::vector<std::uint64_t>> tall_by_end_;  // lone values by the slice they end at
  std::uint32_t released_below_ = 0;
  std::uint64_t held_bytes_ = 0;
  std::uint64_t peak_bytes_ = 0;
};

// All of a structure's values, as VoxelStructure::values() holds them.
class WholeStructureValues final : public StructureValueSource {
 public:
  explicit WholeStructureValues(const VoxelStructure& structure) : values_(structure.values()) {}
  float value(std::uint32_t, std::uint64_t index) const override { return values_[index]; }
  void release_below(std::uint32_t) override {}

 private:
  const std::vector<float>& values_;
};

// The octree writer's slabs from a structure's bricks: full-resolution
// samples, each fine voxel its value and each coarse voxel its value over all
// the voxels it covers, and a keep mask that is 1 exactly on fine voxels
// (StreamingOctreeWriter::add_slab and OctreeSlabBuilder::build take both).
// Slabs come in increasing z and need not follow one another; every voxel of
// a slab must be covered by the structure's bricks. Holds 4 bytes a brick
// and the bricks reaching into the next slab.
class OctreeSlabFiller {
 public:
  explicit OctreeSlabFiller(const VoxelStructure& structure);
  // Slices z0 .. z1 - 1 into `samples` and `keep` ((z1 - z0) x size_y x
  // size_x, [z][y][x]); the values of every brick meeting them must be final.
  void fill(std::uint32_t z0, std::uint32_t z1, const StructureValueSource& values, float* samples, std::uint8_t* keep);

 private:
  const VoxelStructure& structure_;
  std::vector<std::uint32_t> by_first_slice_;
  std::vector<std::uint32_t> open_;  // bricks reaching into the next slab
  std::size_t next_ = 0;
  std::uint32_t last_end_ = 0;
};

// Writes a structure as an .ivol file of its own kind (as write_structure
// does, and the same bytes) part by part: the octree slab by slab through
// StreamingOctreeWriter, the grids' values in file order. Borders and cell
// words, which do not depend on values, are written at construction.
// Peak memory besides the source: the octree writer's slab (its budget in
// `options`) or one block of values, and 8 bytes per brick.
class StructureStreamWriter {
 public:
  StructureStreamWriter(const VoxelStructure& structure, const std::string& path, const StreamingOptions& options);
  // With the metadata known before the first value: a grid's framed file
  // then begins with it (spec §15), so that a cut file keeps it; finish()
  // must be given the same metadata. (The octree's is written first anyway:
  // its file is written at finish().) write_structure() uses this.
  StructureStreamWriter(const VoxelStructure& structure, const std::string& path, const StreamingOptions& options,
                        const Metadata& metadata);
  ~StructureStreamWriter();  // an unfinished writer leaves nothing behind
  StructureStreamWriter(const StructureStreamWriter&) = delete;
  StructureStreamWriter& operator=(const StructureStreamWriter&) = delete;

  // Writes what depends only on voxels starting below slice z_complete (all
  // final in `values`) and releases from `values` what no later part needs.
  void write_ready(std::uint32_t z_complete, StructureValueSource& values);
  // Slices the writer writes at once (the octree's slab; 1 for the grids,
  // written value by value): how far behind z_complete it may release.
  std::uint32_t slab_slices() const;
  // The octree writer's per-subtree index (StreamingOctreeWriter::index_bytes); 0 for the grids.
  std::uint64_t index_bytes() const;
  // Writes the rest (every value must now be final) and renames the file
  // into place.
  StreamingResult finish(const Metadata& metadata, StructureValueSource& values);

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace ivol
