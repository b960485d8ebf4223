// Reading .ivol files: the whole volume, one voxel, a box, a slice, a level of
// detail or a trilinear sample, decompressing only the blocks they touch.
//
// A Reader is not thread-safe; open one Reader per thread (they share nothing
// but the file). Every block read is checked against its CRC-32C; every node
// visited is checked against the rules of spec §8. Errors are ivol::Error.
//
// Resources (spec §13, Resources). Whatever a file claims, a Reader
// allocates only:
// - at open: the parsed index (a BlockInfo per block table entry: the index
//   is checked a MiB at a time, and a claimed index_size is bounded by the
//   bytes of blocks before it), the metadata (at most 16 MiB, nested at most
//   kMaxMetadataDepth), and for the grids of spec §8A their borders or cell
//   words (in proportion to those streams' elements, not to the volume);
// - per request: its output (box.voxel_count() values), and for a level of
//   detail of a grid one double per output voxel of one output layer;
// - decoded blocks up to ReaderOptions::cache_bytes, or the one block in use
//   when it is larger: a block is at most 64 MiB decoded, and its stored
//   size is bounded by its decoded size before it is read (spec §7); a
//   whole level of an octree read on several threads (ReaderOptions::
//   threads) holds a quarter of that budget (at most 32 MiB) shared, plus
//   each thread's block in use at each level, and takes fewer threads, or
//   reads on one thread as other reads do, where these would not fit;
// - for a salvaging read, at most SalvageLog's 1000 DamagedRegion entries.
// Time follows from the voxels asked for (for a level of detail of a grid,
// the full-resolution voxels under it, at most grid_lod_voxels) and the
// blocks they need; a cache
// smaller than the blocks one path through the tree needs (one per level and
// stream) makes reads slower, never larger.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "ivol/geometry.hpp"
#include "ivol/metadata.hpp"

namespace ivol {

struct ReaderOptions {
  // Decoded blocks kept in memory, in bytes: a budget, not a count; the block
  // in use is held even when it alone exceeds it.
  std::uint64_t cache_bytes = 256ull << 20;
  // A level of detail of a grid (spec §8A) sums the full-resolution voxels
  // under it (§12.3): a read whose box covers more is refused
  // (LimitExceeded) rather than run for hours. 2^38 is 64 times a 4000^3
  // volume, a few minutes.
  std::uint64_t grid_lod_voxels = 1ull << 38;
  // When the footer or index cannot be used (a cut copy, a damaged tail):
  // rebuild the index from the framed blocks of a format 1.3 file (spec §18)
  // instead of failing. The Reader then reads what survived; read_box with
  // `damaged` fills the rest from the nearest coarser level and lists it.
  // A file whose index is sound is read as without this option (except that
  // a damaged metadata block gives default metadata instead of an error).
  bool salvage = false;
  // Threads a whole-volume (whole level) read of an octree decodes and walks
  // on; 0: the hardware's, at most 8. Other reads decode their blocks on as
  // many (fetch planning) and walk them on the caller's thread.
  unsigned threads = 0;
  // A bricked grid's levels of detail come from the levels the file stores
  // (spec §8A.5) where it has them: the same bits as summing the
  // full-resolution voxels, without reading them. false: always summed (what
  // check_file compares the stored levels with).
  bool stored_levels = true;
};

// What a salvaging open found (FileInfo::salvage).
struct SalvageInfo {
  std::string reason;              // why the index could not be used
  std::uint64_t blocks_found = 0;  // blocks whose header and payload CRCs hold
  std::uint64_t blocks_used = 0;   // of them, placed in the rebuilt index
  std::uint64_t bytes_lost = 0;    // bytes after the header that are in no found block
  // [begin, end) of those bytes, at most the first 100 runs.
  std::vector<std::pair<std::uint64_t, std::uint64_t>> gaps;
  // "complete" (the metadata block survived), "early" (only the early
  // metadata, stream 6: keys may be missing) or "missing" (defaults).
  std::string metadata = "missing";
  // The finest level of detail every element of which survived; -1: none.
  int finest_complete_lod = -1;
  std::uint64_t values_found = 0;  // values the rebuilt index holds
  std::uint64_t values_total = 0;  // values the volume has; 0 when not known
  std::vector<std::string> notes;  // blocks found but not used, and why (at most 100)
};

// One entry of the block table (spec §6.3).
struct BlockInfo {
  std::uint64_t file_offset = 0;
  std::uint64_t first_element = 0;
  std::uint32_t element_count = 0;
  std::uint32_t stored_size = 0;
  std::uint32_t crc = 0;
  std::uint8_t stream = 0;
  std::uint8_t codec = 0;
  std::uint8_t flags = 0;
  std::uint8_t level = 0;
};

const char* stream_name(std::uint8_t stream);  // "metadata", "nodes", "values" or "stream N"

// What the header, footer and index say.
struct FileInfo {
  std::uint16_t version_major = 0;
  std::uint16_t version_minor = 0;
  std::uint32_t header_size = 0;
  std::uint64_t required_features = 0;
  std::uint64_t optional_features = 0;
  std::uint64_t file_size = 0;
  std::uint64_t index_offset = 0;
  std::uint64_t index_size = 0;
  VolumeLayout layout;
  std::vector<BlockInfo> blocks;
  // Format 1.3 framed blocks (required feature bit 0): every block's stored
  // bytes begin with a 32-byte block header.
  bool framed() const { return (required_features & 1u) != 0; }
  // Set when the index was rebuilt by scanning the blocks (ReaderOptions::
  // salvage): what was found and what is missing.
  std::shared_ptr<const SalvageInfo> salvage;
};

// A region a salvaging read filled from a coarser level because a block it
// needed is damaged or missing: `region` in the coordinates of the read's
// level of detail, `level` the octree level where the damage was met. One
// entry per damaged block or missing run of elements (`message` names it),
// its region the box around all it cost; at most 1001 entries a read. The
// grids of spec §8A have no coarser level: their missing cells read as the
// stored code 0.
struct DamagedRegion {
  Box region;
  unsigned level = 0;
  std::string message;
};

struct IoStats {
  std::uint64_t bytes_read = 0;  // bytes read from the file, all parts
  // Round trips to the storage and the bytes they brought: for a local file
  // the reads and bytes_read; over HTTP(S) the range requests and the whole
  // pages they fetched (a path starting http:// or https:// opens a remote
  // file, read by range).
  std::uint64_t requests = 0;
  std::uint64_t bytes_fetched = 0;
  std::uint64_t blocks_decoded = 0;  // blocks read, checked and decompressed
  std::uint64_t cache_hits = 0;
  // The server ignored range requests: the whole file came in one response
  // and is held in memory (allowed up to the HTTP cache's size,
  // IVOL_HTTP_CACHE_MIB; a larger file is refused). Worth a warning: every
  // open of the file downloads it whole.
  bool fetched_whole = false;
};

struct CheckReport;

// Whether a Reader opens `path` remotely, by byte ranges: an http://,
// https:// or s3:// address.
bool is_remote_path(const std::string& path);

class Reader {
 public:
  // Reads and checks the header, footer, index and metadata.
  explicit Reader(const std::string& path, const ReaderOptions& options = {});
  ~Reader();
  Reader(Reader&&) noexcept;
  Reader& operator=(Reader&&) noexcept;

  const std::string& path() const;
  const FileInfo& info() const;
  const VolumeLayout& layout() const;
  const Metadata& metadata() const;
  // Why the metadata block could not be read, where a salvaging reader
  // (ReaderOptions::salvage) opened the file with the defaults standing in
  // (a damaged block, or none found by a rebuilt index); empty when it was
  // read. (After a rebuilt index that found only the early metadata,
  // info().salvage says "early".)
  const std::string& metadata_problem() const;

  std::uint32_t voxel_bits(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod = 0);
  double voxel_value(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod = 0);

  // Physical values of `box` (in the coordinates of level of detail `lod`),
  // [z][y][x] with x fastest.
  // With `damaged`, blocks that fail their checks do not stop the read: their
  // regions take the average of the nearest readable ancestor (a coarser
  // level) and are listed in *damaged (salvage).
  std::vector<float> read_box(const Box& box, unsigned lod = 0, std::vector<DamagedRegion>* damaged = nullptr);
  // The same into the caller's `out`, box.voxel_count() floats: a caller
  // that holds its own array (the Python package's) saves allocating,
  // zeroing and copying one.
  void read_box_into(const Box& box, float* out, unsigned lod = 0, std::vector<DamagedRegion>* damaged = nullptr);
  // Stored bits of `box`, encoding_width() bytes per voxel, little-endian.
  std::vector<std::uint8_t> read_box_bits(const Box& box, unsigned lod = 0,
                                          std::vector<DamagedRegion>* damaged = nullptr);
  // The same into the caller's `out`, box.voxel_count() * encoding_width()
  // bytes (numpy's array for the Python package's f.stored[...]); `out`
  // aligned for the encoding's width.
  void read_box_bits_into(const Box& box, void* out, unsigned lod = 0, std::vector<DamagedRegion>* damaged = nullptr);
  std::vector<float> read_slice(Axis axis, std::uint32_t index);
  // The whole volume at 1/2^lod resolution (spec §12.3).
  std::vector<float> read_lod(unsigned lod);
  // Calls visit(region, value) for every leaf that meets `box` (and, at a
  // level of detail, every node of that level), with `region` the part of the
  // box it covers and `value` its physical value: the structure itself, e.g.
  // to draw where resolution was kept.
  void visit_leaves(const Box& box, unsigned lod, const std::function<void(const Box&, double)>& visit);
  // Trilinear interpolation between voxel centres at a world position (spec
  // §12.1); positions outside the volume take the nearest border voxel.
  double sample(double world_x, double world_y, double world_z);

  // Reads, checks and decodes one block of the block table.
  std::vector<std::uint8_t> read_block(std::size_t block_index);

  const IoStats& io_stats() const;
  void reset_io_stats();

  struct Impl;  // internal

 private:
  friend CheckReport check_file(const std::string& path);
  std::unique_ptr<Impl> impl_;
};

}  // namespace ivol
