#include "block_reader.hpp"

#include <zstd.h>
#include <zstd_errors.h>

#include <cstring>

#include "framing.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

constexpr unsigned char kZstdMagic[4] = {0x28, 0xB5, 0x2F, 0xFD};

}  // namespace

std::vector<std::uint8_t> read_and_decode_block(RandomAccessFile& file, const BlockInfo& block, std::size_t index,
                                                std::size_t width, bool known, bool framed) {
  const std::string part = file.path() + ": block " + std::to_string(index) + " (" + stream_name(block.stream) +
                           ", level " + std::to_string(block.level) + ", elements " +
                           std::to_string(block.first_element) + " .. " +
                           std::to_string(block.first_element + block.element_count) + ", offset " +
                           std::to_string(block.file_offset) + "): ";
  std::vector<std::uint8_t> stored = file.read(block.file_offset, block.stored_size);
  const std::uint32_t actual = crc32c(stored.data(), stored.size());
  if (actual != block.crc) {
    char text[96];
    std::snprintf(text, sizeof text, "CRC-32C is 0x%08X but the index says 0x%08X", actual, block.crc);
    throw Error(ErrorClass::Checksum, part + text);
  }
  if (framed) {  // spec §7.1: the block header repeats the index entry; the payload follows it
    check_block_header(stored.data(), stored.size(), block, part);
    stored.erase(stored.begin(), stored.begin() + 32);
  }
  // A block of a stream this reader does not know (ignorable, or the index
  // would have been refused): its CRC is all that can be checked.
  if (!known) return stored;
  const std::size_t decoded_size = std::size_t{block.element_count} * width;
  if (block.codec == 0) return stored;
  if (block.codec != 1 && block.codec != 2)
    throw Error(ErrorClass::UnsupportedFeature, part + "codec " + std::to_string(block.codec) + " is not known");

  if (stored.size() < 4 || std::memcmp(stored.data(), kZstdMagic, 4) != 0)
    throw Error(ErrorClass::Malformed, part + "the stored bytes are not a zstd frame");
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content == ZSTD_CONTENTSIZE_UNKNOWN)
    throw Error(ErrorClass::Malformed, part + "the zstd frame does not carry Frame_Content_Size");
  if (content == ZSTD_CONTENTSIZE_ERROR) throw Error(ErrorClass::Malformed, part + "the zstd frame header is invalid");
  if (content != decoded_size)
    throw Error(ErrorClass::Malformed, part + "the zstd frame holds " + std::to_string(content) +
                                           " bytes, the index says " + std::to_string(decoded_size));
  if (ZSTD_getDictID_fromFrame(stored.data(), stored.size()) != 0)
    throw Error(ErrorClass::Malformed, part + "the zstd frame needs a dictionary");
  const std::size_t frame_size = ZSTD_findFrameCompressedSize(stored.data(), stored.size());
  if (ZSTD_isError(frame_size) || frame_size != stored.size())
    throw Error(ErrorClass::Malformed, part + "the stored bytes are not exactly one complete zstd frame");

  thread_local std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> context(ZSTD_createDCtx(), ZSTD_freeDCtx);
  std::vector<std::uint8_t> decoded(decoded_size);
  const std::size_t got =
      ZSTD_decompressDCtx(context.get(), decoded.data(), decoded.size(), stored.data(), stored.size());
  if (ZSTD_isError(got)) {
    if (ZSTD_getErrorCode(got) == ZSTD_error_checksum_wrong)
      throw Error(ErrorClass::Checksum, part + "the zstd content checksum does not match");
    throw Error(ErrorClass::Malformed, part + "zstd cannot decode it: " + ZSTD_getErrorName(got));
  }
  if (got != decoded_size)
    throw Error(ErrorClass::Malformed,
                part + "decoded to " + std::to_string(got) + " bytes, expected " + std::to_string(decoded_size));
  if (block.codec == 2 && width > 1) {  // byte planes back into elements
    std::vector<std::uint8_t> elements(decoded_size);
    const std::size_t n = block.element_count;
    for (std::size_t p = 0; p < width; ++p)
      for (std::size_t i = 0; i < n; ++i) elements[i * width + p] = decoded[p * n + i];
    return elements;
  }
  return decoded;
}

BlockData BlockCache::find(std::size_t block) {
  const auto it = entries_.find(block);
  if (it == entries_.end()) return nullptr;
  order_.splice(order_.begin(), order_, it->second.position);
  return it->second.data;
}

void BlockCache::insert(std::size_t block, BlockData data) {
  if (entries_.count(block)) return;
  used_ += data->size();
  order_.push_front(block);
  entries_.emplace(block, Entry{std::move(data), order_.begin()});
  // Keep at least a handful of blocks whatever the budget, so that a walk
  // touching one block per level does not thrash.
  while (used_ > capacity_ && entries_.size() > 64) {
    const std::size_t victim = order_.back();
    order_.pop_back();
    used_ -= entries_[victim].data->size();
    entries_.erase(victim);
  }
}

}  // namespace ivol::detail
