// Writing an octree from slabs of a volume that need not fit in memory.
//
// The volume arrives as slabs of 2^s slices (z increasing). Each slab is cut
// into subtrees of side 2^s, built at once (in parallel), and spilled to a
// temporary file (spill_directory_for). finish() builds the levels above the
// subtrees from their roots and writes the file level by level, reading the
// spilled subtrees in Morton order. Peak memory: one slab of samples (and its
// keep mask), one subtree per thread, the subtrees' roots and spill index
// (about 32·(s + 2) bytes per subtree), the levels above them, and one batch
// of blocks. The temporary spill file holds the octree's node words and
// values compressed as the file's blocks are (zstd over byte planes), in
// chunks of one level of one subtree; it has no name (O_TMPFILE, or unlinked
// at once), so it never outlives the process.
//
// The result is the same file, bit for bit, as build_octree + write_octree
// give for the same volume and options, whatever the slab thickness (tested).
// A slab's subtrees can also be built elsewhere (OctreeSlabBuilder, in
// ivol/octree_slab_builder.hpp: on another rank of a distributed run) and
// given as they are (add_built_slab), with the same result.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "ivol/build.hpp"
#include "ivol/metadata.hpp"
#include "ivol/writer.hpp"

namespace ivol {

struct BuiltSlab;  // ivol/octree_slab_builder.hpp

struct StreamingOptions {
  BuildOptions build;  // its keep_mask is ignored: masks come with each slab
  WriteOptions write;
  // Slab thickness in slices, a power of two; 0: the largest one whose float32
  // samples and subtree index (index_bytes()) fit in `slab_budget_bytes` (at
  // least 8 slices, or the volume; when none fits, the one needing least).
  std::uint32_t slab_slices = 0;
  std::uint64_t slab_budget_bytes = 512ull << 20;
  // Where the temporary spill file goes: this directory; empty: $TMPDIR when
  // set and not empty, else the output's directory (spill_directory_for).
  std::string spill_directory;
  // zstd level of the spill file's chunks (byte planes, as the file's blocks).
  int spill_zstd_level = 1;
};

// The directory the spill file of an output at `output_path` goes to, by
// the precedence above.
std::string spill_directory_for(const std::string& output_path, const std::string& spill_directory);

struct StreamingResult {
  WriteStats write;
  double max_abs_error = 0.0;
  bool lossless = true;
  std::uint64_t kept_voxels = 0;
  std::uint64_t spill_bytes = 0;  // largest size of the temporary spill file (compressed)
  std::string spill_directory;    // where it was
  double build_seconds = 0.0;     // building subtrees and the top levels
};

class StreamingOctreeWriter {
 public:
  StreamingOctreeWriter(const std::string& path, const Dims& dims, const StreamingOptions& options);
  ~StreamingOctreeWriter();  // an unfinished writer leaves nothing behind
  StreamingOctreeWriter(const StreamingOctreeWriter&) = delete;
  StreamingOctreeWriter& operator=(const StreamingOctreeWriter&) = delete;

  std::uint32_t slab_slices() const;
  // Bytes it holds until finish() for each subtree of a slab (records,
  // per-level counts): (dims / slab_slices)^3 of them; counted, with the
  // samples, when the slab thickness is chosen.
  std::uint64_t index_bytes() const;
  // Slices z0 .. z0 + slices of the next slab (the last slab may be thinner).
  std::uint32_t next_slab_first() const;
  std::uint32_t next_slab_count() const;

  // Adds the next slab: next_slab_count() slices of size_y x size_x samples,
  // [z][y][x]; `keep` (optional, same shape) marks voxels whose full
  // resolution must be kept, the rest being coarsened (null: lossless).
  // Either every slab has a mask or none.
  void add_slab(const float* samples, const std::uint8_t* keep = nullptr);
  void add_slab(const std::uint16_t* samples, const std::uint8_t* keep = nullptr);
  // Adds the next slab built by an OctreeSlabBuilder (possibly in another
  // process) with this writer's dims and options: exactly the effect of
  // add_slab with the samples and mask it was built from. Throws
  // ivol::Error naming both layouts for a slab of another layout (dims, slab
  // thickness, encoding, scale, offset, sample type), and naming both
  // indices for a slab out of order.
  void add_built_slab(const BuiltSlab& built);

  // Called once the whole octree is known, before the metadata is written:
  // lets the caller record the outcome (lossless, largest error) in it.
  using AmendMetadata = std::function<void(Metadata& metadata, const StreamingResult& outcome)>;

  // After the last slab: writes the file and renames it into place.
  StreamingResult finish(const Metadata& metadata, const AmendMetadata& amend = {});

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<struct StreamingState> pending_;
};

}  // namespace ivol
