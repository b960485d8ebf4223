#include "block_pipeline.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include "ivol/error.hpp"
#include "thread_parts.hpp"

namespace ivol {

namespace {

unsigned thread_count(const WriteOptions& options) {
  return std::max(1u, options.threads ? options.threads : std::thread::hardware_concurrency());
}

}  // namespace

std::vector<EncodedBlock> encode_blocks(const RawBlock* blocks, std::size_t count, const WriteOptions& options) {
  std::vector<EncodedBlock> encoded(count);
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t i; (i = next.fetch_add(1)) < count;) {
      const RawBlock& b = blocks[i];
      encoded[i] = encode_block(b.stream, b.level, b.first_element, b.element_count, b.width, b.bytes.data(), options);
    }
  };
  detail::run_parts(
      static_cast<unsigned>(std::max<std::size_t>(1, std::min<std::size_t>(thread_count(options), count))),
      [&](unsigned) { work(); });
  return encoded;
}

namespace detail {

BlockPipeline::BlockPipeline(FileWriter& writer, const WriteOptions& options)
    : writer_(writer),
      options_(options),
      batch_blocks_(options.encoder ? std::max<std::size_t>(1, options.encoder->batch_blocks())
                                    : 4 * thread_count(options)) {}

void BlockPipeline::add(Stream stream, unsigned level, std::uint64_t first_element, std::uint32_t element_count,
                        std::size_t width, std::vector<std::uint8_t> raw) {
  decoded_bytes_ += raw.size();
  pending_.push_back({stream, static_cast<std::uint8_t>(level), first_element, element_count,
                      static_cast<std::uint32_t>(width), std::move(raw)});
  if (pending_.size() >= batch_blocks_) flush();
}

void BlockPipeline::flush() {
  if (pending_.empty()) return;
  const std::vector<EncodedBlock> encoded =
      options_.encoder ? options_.encoder->encode(pending_, options_) : encode_blocks(pending_, options_);
  if (encoded.size() != pending_.size())
    throw Error(ErrorClass::Io, "block encoder returned " + std::to_string(encoded.size()) + " blocks for " +
                                    std::to_string(pending_.size()));
  for (const EncodedBlock& block : encoded) writer_.append(block);
  pending_.clear();
}

BlockAssembler::BlockAssembler(BlockPipeline& pipeline, Stream stream, unsigned level, std::uint64_t first_element,
                               std::size_t width, std::uint32_t block_bytes)
    : pipeline_(pipeline),
      stream_(stream),
      level_(level),
      next_element_(first_element),
      width_(width),
      per_block_(std::max<std::uint64_t>(1, block_bytes / width)) {}

void BlockAssembler::append(const void* elements, std::uint64_t count) {
  const auto* p = static_cast<const std::uint8_t*>(elements);
  while (count > 0) {
    const std::uint64_t room = per_block_ - buffer_.size() / width_;
    const std::uint64_t take = std::min(room, count);
    buffer_.insert(buffer_.end(), p, p + take * width_);
    p += take * width_;
    count -= take;
    if (buffer_.size() / width_ == per_block_) finish();
  }
}

void BlockAssembler::finish() {
  if (buffer_.empty()) return;
  const auto count = static_cast<std::uint32_t>(buffer_.size() / width_);
  pipeline_.add(stream_, level_, next_element_, count, width_, std::move(buffer_));
  next_element_ += count;
  buffer_ = {};
}

}  // namespace detail
}  // namespace ivol
