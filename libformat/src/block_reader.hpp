// Reading one block: its CRC, its codec, its decoded size (spec §7); and a
// least-recently-used cache of decoded blocks. Internal to libformat.
#pragma once

#include <cstdint>
#include <list>
#include <memory>
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
std::vector<std::uint8_t> read_and_decode_block(RandomAccessFile& file, const BlockInfo& block, std::size_t index,
                                                std::size_t width, bool known, bool framed);

using BlockData = std::shared_ptr<const std::vector<std::uint8_t>>;

class BlockCache {
 public:
  explicit BlockCache(std::uint64_t capacity_bytes) : capacity_(capacity_bytes) {}
  BlockData find(std::size_t block);
  void insert(std::size_t block, BlockData data);

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
