// Reading one block: its CRC, its codec, its decoded size (spec §7); and a
// least-recently-used cache of decoded blocks. Internal to libformat.
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

#include "ivol/reader.hpp"
#include "random_access_file.hpp"

namespace ivol::detail {

// Reads, checks and decodes block `index` of the block table; `width` is the
// element width of its stream.
// A block of a stream unknown to the file's kind is only checked against its
// CRC (`known` false). `framed`: format 1.3, the stored bytes begin with a
// block header, checked against `block` and not part of what is returned.
// `brick`: the brick of a bricked grid's values block (brick_grid.hpp), which
// codec 3 needs; a block of codec 3 without one is malformed.
std::vector<std::uint8_t> read_and_decode_block(RandomAccessFile& file, const BlockInfo& block, std::size_t index,
                                                std::size_t width, bool known, bool framed,
                                                const std::optional<Dims>& brick = std::nullopt);
// The same for a known stream's block whose stored bytes the caller read
// (a batch of blocks is read together, then decoded on several threads):
// thread-safe, `path` only names the file in errors.
std::vector<std::uint8_t> decode_stored_block(const std::string& path, const BlockInfo& block, std::size_t index,
                                              std::size_t width, bool framed, const std::optional<Dims>& brick,
                                              std::vector<std::uint8_t> stored);
// The same into `out` (element_count * width bytes) from `stored_size`
// stored bytes at `stored`: no buffer allocated per block.
void decode_stored_into(const std::string& path, const BlockInfo& block, std::size_t index, std::size_t width,
                        bool framed, const std::optional<Dims>& brick, const std::uint8_t* stored,
                        std::size_t stored_size, std::uint8_t* out);
// Checks block `index`'s CRC a chunk at a time (Error(Checksum) if it fails),
// holding 1 MiB whatever its stored size.
void check_block_crc(RandomAccessFile& file, const BlockInfo& block, std::size_t index);
std::uint32_t crc32c_of_range(RandomAccessFile& file, std::uint64_t offset, std::uint64_t size);

using BlockData = std::shared_ptr<const std::vector<std::uint8_t>>;

// Decoded blocks up to a byte budget, least recently used first out; the
// block inserted last is kept even when it alone exceeds the budget.
class BlockCache {
 public:
  explicit BlockCache(std::uint64_t capacity_bytes) : capacity_(capacity_bytes) {}
  std::uint64_t capacity() const { return capacity_; }
  bool contains(std::size_t block) const { return entries_.count(block) != 0; }
  BlockData find(std::size_t block);
  // Returns the blocks evicted to make room, so that the caller can drop
  // other references to them (the memory is freed only then).
  std::vector<std::size_t> insert(std::size_t block, BlockData data);

 private:
  struct Entry {
    BlockData data;
    std::list<std::size_t>::iterator position;
  };
  std::uint64_t capacity_;
  std::uint64_t used_ = 0;
  std::list<std::size_t> order_;  // most recent first
  std::unordered_map<std::size_t, Entry> entries_;
};

}  // namespace ivol::detail
