// Writing .ivol files. FileWriter streams blocks to a temporary file in one
// pass, keeping only the block table in memory, and renames the file into
// place when the footer is written (spec §15). write_octree() writes a whole
// in-memory octree through it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/geometry.hpp"
#include "ivol/metadata.hpp"
#include "ivol/octree.hpp"

namespace ivol {

class BlockEncoder;  // ivol/block_encoder.hpp

// StoredLevel: a bricked grid's stored level of detail (spec §8A.5; format
// 1.3), an ignorable stream: its blocks carry the ignorable flag.
enum class Stream : std::uint8_t {
  Metadata = 1,
  Nodes = 2,
  Values = 3,
  Borders = 4,
  Cells = 5,
  EarlyMetadata = 6,  // ignorable: the metadata as known before the values (spec §15)
  StoredLevel = 7,
};
// Spec §7. ZstdBytePlanes: zstd over the elements' bytes regrouped by byte
// position (since format 1.2). Predicted: a brick of 16-bit values, predicted
// (ivol/predicted_codec.hpp; format 1.3). ZstdPlaneFrames: the same byte
// planes, a zstd frame each (format 1.3).
enum class Codec : std::uint8_t {
  Stored = 0,
  Zstd = 1,
  ZstdBytePlanes = 2,
  Predicted = 3,
  Masked = 4,
  ZstdPlaneFrames = 5,
  TopByte = 6
};

// From this zstd level on, framed (format 1.3) files hold byte planes of
// at least kPlaneFramesFromElements elements of 2 or 4 bytes as codec 5, a
// frame each, instead of codec 2: zstd's optimal parser, which these levels
// use, prices matches by the statistics of the frame's earlier blocks, and
// the noisy low planes of CT values mislead it on the smooth high ones
// (float32 bricks 0.6-1.1 % smaller at levels 13-19; at level 9 and below
// codec 2 is as small). Smaller planes, and the eight planes of 16 KiB of
// node words, pay more in frame headers and checksums than they gain
// (bench/RESULTS.md, issue 22, "Codec 5").
inline constexpr int kPlaneFramesFromLevel = 13;
inline constexpr std::uint32_t kPlaneFramesFromElements = 4096;

struct WriteOptions {
  // Decoded bytes per block, at most. Small blocks make slices and regions
  // cheap to read; 16 KiB keeps a 512^3 slice near 10 % of an octree file and
  // a 64^3 region under 5 %, for 1 % more file than 1 MiB blocks (bench/).
  std::uint32_t block_bytes = 16 * 1024;
  int zstd_level = 3;
  bool compress = true;  // false: every block stored (codec 0)
  // Blocks of elements wider than a byte (node words, values, borders, cell
  // words) over byte planes (codec 2, format 1.2): 7 % smaller for an octree
  // of noisy CT values; false writes codec 1 only, for format 1.0 / 1.1
  // readers.
  bool byte_planes = true;
  // Format 1.3 framing (required feature bit 0): a block header before every
  // block, the volume descriptor in the file header and the metadata first,
  // so that a cut or damaged file can be salvaged without its index; false
  // writes format 1.2 files (no framing) for readers older than 1.3. Blocks
  // are framed where they are appended, so an encoder (below) never sees it.
  bool framed_blocks = true;
  unsigned threads = 0;  // compression threads; 0: all hardware threads
  // Where batches of blocks are compressed; null: on this process's threads.
  // The file is the same either way (ivol/block_encoder.hpp).
  std::shared_ptr<BlockEncoder> encoder;
};

// One block, compressed and checksummed, ready to be appended.
struct EncodedBlock {
  Stream stream = Stream::Values;
  std::uint8_t level = 0;
  std::uint64_t first_element = 0;
  std::uint32_t element_count = 0;
  Codec codec = Codec::Stored;
  std::uint32_t crc = 0;
  std::vector<std::uint8_t> bytes;
};

// Compresses `element_count` elements of `width` bytes (zstd with content size
// and checksum; stored when zstd does not make them smaller).
EncodedBlock encode_block(Stream stream, unsigned level, std::uint64_t first_element, std::uint32_t element_count,
                          std::size_t width, const void* data, const WriteOptions& options);

class FileWriter {
 public:
  // `layout` gives dims, encoding, scale and offset; its inner_count is given
  // to finish(). Creates a temporary file next to `path`. `framed`: format
  // 1.3 framed blocks (WriteOptions::framed_blocks).
  FileWriter(const std::string& path, const VolumeLayout& layout, bool framed = true);
  ~FileWriter();  // an unfinished file is removed; nothing at `path` changes
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;

  void append(const EncodedBlock& block);
  // Writes the metadata block now: writers of framed files call it before the
  // first value (spec §15), so that a cut file keeps its metadata.
  void write_metadata(const Metadata& metadata);
  // Writes an early metadata block (stream 6, ignorable; spec §15): for a
  // writer that learns part of its metadata only after the values (the
  // sources' digests, what rounding lost), what it knows before them, so
  // that a file cut before its metadata block still has voxel size, origin
  // and unit for salvage. Framed files only (nothing is written otherwise);
  // before the first value.
  void write_early_metadata(const Metadata& metadata);
  // Writes the metadata block unless write_metadata() did (then `metadata`
  // must be the same), the index and the footer, flushes, and renames the
  // temporary file to `path` (replacing any file there atomically).
  void finish(const Metadata& metadata, const std::vector<std::uint64_t>& inner_count);
  bool framed() const { return framed_; }

  std::uint64_t bytes_written() const { return offset_; }
  std::uint64_t block_count() const { return entries_.size(); }

 private:
  struct Entry {
    std::uint64_t file_offset;
    std::uint64_t first_element;
    std::uint32_t element_count;
    std::uint32_t stored_size;
    std::uint32_t crc;
    std::uint8_t stream;
    std::uint8_t codec;
    std::uint8_t level;
    std::uint8_t flags;
  };
  void write_all(const void* data, std::size_t size, const char* what);

  std::string path_;
  std::string temp_path_;
  VolumeLayout layout_;
  bool framed_ = true;
  std::string metadata_json_;  // as written by write_metadata(); empty until then
  int fd_ = -1;
  std::uint64_t offset_ = 0;
  std::uint64_t writeback_from_ = 0;  // bytes before it were handed to the disk early (write_all)
  std::vector<Entry> entries_;
  bool finished_ = false;
};

struct WriteStats {
  std::uint64_t file_bytes = 0;
  std::uint64_t decoded_bytes = 0;  // nodes + values + metadata before compression
  std::uint64_t block_count = 0;
  double seconds = 0.0;
};

WriteStats write_octree(const Octree& octree, const Metadata& metadata, const std::string& path,
                        const WriteOptions& options = {});

}  // namespace ivol
