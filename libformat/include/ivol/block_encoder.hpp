// Compressing a file's blocks somewhere other than the writing thread. A
// writer collects its blocks in batches; by default it compresses a batch on
// its own threads (encode_blocks). A BlockEncoder given in
// WriteOptions::encoder takes the batches instead: tools/cli hands them to
// the other ranks of a distributed run, so that one process need not
// compress a whole 4000³ volume alone. libformat knows nothing of how.
//
// The file does not depend on where a block was compressed: encode_block's
// output depends only on the block and on zstd_level, compress and
// byte_planes (zstd is deterministic for the same input and parameters, and
// no thread-count-dependent parameter is set), so an encoder must only use
// the same three options.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/writer.hpp"

namespace ivol {

// One block's elements before compression.
struct RawBlock {
  Stream stream = Stream::Values;
  std::uint8_t level = 0;
  std::uint64_t first_element = 0;
  std::uint32_t element_count = 0;
  std::uint32_t width = 1;  // bytes per element
  std::vector<std::uint8_t> bytes;
};

// Compresses a batch with encode_block on `options.threads` threads (0: all
// hardware threads); the result is in the batch's order.
std::vector<EncodedBlock> encode_blocks(const RawBlock* blocks, std::size_t count, const WriteOptions& options);
inline std::vector<EncodedBlock> encode_blocks(const std::vector<RawBlock>& batch, const WriteOptions& options) {
  return encode_blocks(batch.data(), batch.size(), options);
}

class BlockEncoder {
 public:
  virtual ~BlockEncoder() = default;
  // How many blocks the writer collects before calling encode().
  virtual std::size_t batch_blocks() const = 0;
  // Must return what encode_blocks(batch, options) returns, in the same
  // order; throws to make the write fail (the writer then removes its
  // temporary file). Called by one thread at a time: the writer's.
  virtual std::vector<EncodedBlock> encode(const std::vector<RawBlock>& batch, const WriteOptions& options) = 0;
};

}  // namespace ivol
