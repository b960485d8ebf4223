// Compresses blocks in parallel, a batch at a time, and appends them to a
// FileWriter in the order they were given: on this process's threads, or
// through WriteOptions::encoder. Memory: one batch of blocks. Internal to
// libformat.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/block_encoder.hpp"
#include "ivol/writer.hpp"

namespace ivol::detail {

class BlockPipeline {
 public:
  BlockPipeline(FileWriter& writer, const WriteOptions& options);
  // Takes one block's decoded elements.
  void add(Stream stream, unsigned level, std::uint64_t first_element, std::uint32_t element_count, std::size_t width,
           std::vector<std::uint8_t> raw);
  void flush();
  std::uint64_t decoded_bytes() const { return decoded_bytes_; }

 private:
  FileWriter& writer_;
  WriteOptions options_;
  std::size_t batch_blocks_;
  std::vector<RawBlock> pending_;
  std::uint64_t decoded_bytes_ = 0;
};

// Cuts a stream of elements of one level into blocks of at most
// options.block_bytes and hands them to a pipeline.
class BlockAssembler {
 public:
  BlockAssembler(BlockPipeline& pipeline, Stream stream, unsigned level, std::uint64_t first_element, std::size_t width,
                 std::uint32_t block_bytes);
  ~BlockAssembler() = default;
  void append(const void* elements, std::uint64_t count);
  void finish();  // hands over the last, partial block

 private:
  BlockPipeline& pipeline_;
  Stream stream_;
  unsigned level_;
  std::uint64_t next_element_;
  std::size_t width_;
  std::uint64_t per_block_;
  std::vector<std::uint8_t> buffer_;
};

}  // namespace ivol::detail
