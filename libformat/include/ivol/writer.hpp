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

enum class Stream : std::uint8_t { Metadata = 1, Nodes = 2, Values = 3, Borders = 4, Cells = 5 };
// Spec §7. ZstdBytePlanes: zstd over the elements' bytes regrouped by byte
// position (since format 1.2).
enum class Codec : std::uint8_t { Stored = 0, Zstd = 1, ZstdBytePlanes = 2 };

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
  // to finish(). Creates a temporary file next to `path`.
  FileWriter(const std::string& path, const VolumeLayout& layout);
  ~FileWriter();  // an unfinished file is removed; nothing at `path` changes
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;

  void append(const EncodedBlock& block);
  // Writes the metadata block, the index and the footer, flushes, and renames
  // the temporary file to `path` (replacing any file there atomically).
  void finish(const Metadata& metadata, const std::vector<std::uint64_t>& inner_count);

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
  };
  void write_all(const void* data, std::size_t size, const char* what);

  std::string path_;
  std::string temp_path_;
  VolumeLayout layout_;
  int fd_ = -1;
  std::uint64_t offset_ = 0;
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
