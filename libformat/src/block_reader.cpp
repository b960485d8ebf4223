#include "block_reader.hpp"

#include <zstd.h>
#include <zstd_errors.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>

#include "framing.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/masked_codec.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/top_byte_codec.hpp"
#include "layout.hpp"
#include "zstd_parts.hpp"

namespace ivol::detail {
namespace {

constexpr unsigned char kZstdMagic[4] = {0x28, 0xB5, 0x2F, 0xFD};

std::string crc_text(std::uint32_t actual, std::uint32_t expected) {
  char text[96];
  std::snprintf(text, sizeof text, "CRC-32C is 0x%08X but the index says 0x%08X", actual, expected);
  return text;
}

std::string block_part(const std::string& path, const BlockInfo& block, std::size_t index) {
  return path + ": block " + std::to_string(index) + " (" + stream_name(block.stream) + ", level " +
         std::to_string(block.level) + ", elements " + std::to_string(block.first_element) + " .. " +
         std::to_string(block.first_element + block.element_count) + ", offset " + std::to_string(block.file_offset) +
         "): ";
}

// Codec 2's byte planes (plane p holds byte p of every element) back into
// `n` elements of Width bytes.
template <std::size_t Width>
void unshuffle(const std::uint8_t* planes, std::size_t n, std::uint8_t* elements) {
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t p = 0; p < Width; ++p) elements[i * Width + p] = planes[p * n + i];
}

// The length of the zstd frame that starts at `frame` (of at most
// `available` bytes), checked under codec 1's rules (spec §7):
// Frame_Content_Size present and equal to content_size, no dictionary.
std::size_t zstd_frame_size(const std::string& part, const std::string& which, const std::uint8_t* frame,
                            std::size_t available, std::size_t content_size) {
  if (available < 4 || std::memcmp(frame, kZstdMagic, 4) != 0)
    throw Error(ErrorClass::Malformed, part + which + " does not start with zstd's magic number");
  const unsigned long long content = ZSTD_getFrameContentSize(frame, available);
  if (content == ZSTD_CONTENTSIZE_UNKNOWN)
    throw Error(ErrorClass::Malformed, part + which + " does not carry Frame_Content_Size");
  if (content == ZSTD_CONTENTSIZE_ERROR) throw Error(ErrorClass::Malformed, part + which + ": its header is invalid");
  if (content != content_size)
    throw Error(ErrorClass::Malformed, part + which + " holds " + std::to_string(content) + " bytes, the index says " +
                                           std::to_string(content_size));
  if (ZSTD_getDictID_fromFrame(frame, available) != 0)
    throw Error(ErrorClass::Malformed, part + which + " needs a dictionary");
  const std::size_t frame_size = ZSTD_findFrameCompressedSize(frame, available);
  if (ZSTD_isError(frame_size))
    throw Error(ErrorClass::Malformed, part + which + " does not end within the stored bytes");
  return frame_size;
}

// Decodes a frame of `frame_size` bytes that zstd_frame_size() checked into
// its `content_size` bytes at `out`, the content checksum verified when
// present.
void decode_zstd_frame(const std::string& part, const std::string& which, const std::uint8_t* frame,
                       std::size_t frame_size, std::size_t content_size, std::uint8_t* out) {
  ZSTD_DCtx* const context = detail::thread_decompression_context();
  const std::size_t got = ZSTD_decompressDCtx(context, out, content_size, frame, frame_size);
  if (ZSTD_isError(got)) {
    if (ZSTD_getErrorCode(got) == ZSTD_error_checksum_wrong)
      throw Error(ErrorClass::Checksum, part + which + ": the zstd content checksum does not match");
    throw Error(ErrorClass::Malformed, part + "zstd cannot decode " + which + ": " + ZSTD_getErrorName(got));
  }
  if (got != content_size)
    throw Error(ErrorClass::Malformed, part + which + " decoded to " + std::to_string(got) + " bytes, expected " +
                                           std::to_string(content_size));
}

}  // namespace

void check_block_crc(RandomAccessFile& file, const BlockInfo& block, std::size_t index) {
  const std::uint32_t actual = crc32c_of_range(file, block.file_offset, block.stored_size);
  if (actual != block.crc)
    throw Error(ErrorClass::Checksum, block_part(file.path(), block, index) + crc_text(actual, block.crc));
}

std::uint32_t crc32c_of_range(RandomAccessFile& file, std::uint64_t offset, std::uint64_t size) {
  constexpr std::size_t kChunk = 1u << 20;
  std::vector<std::uint8_t> chunk(static_cast<std::size_t>(std::min<std::uint64_t>(size, kChunk)));
  std::uint32_t crc = 0;
  for (std::uint64_t done = 0; done < size;) {
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(size - done, kChunk));
    file.read(offset + done, chunk.data(), n);
    crc = crc32c_extend(crc, chunk.data(), n);
    done += n;
  }
  return crc;
}

std::vector<std::uint8_t> read_and_decode_block(RandomAccessFile& file, const BlockInfo& block, std::size_t index,
                                                std::size_t width, bool known, bool framed,
                                                const std::optional<Dims>& brick) {
  const std::string part = block_part(file.path(), block, index);
  // A block of a stream this reader does not know (ignorable, or the index
  // would have been refused) has no size limit but the file's (spec §6.4):
  // its CRCs are checked while streaming, before anything is allocated for
  // it, and nothing of it is returned.
  if (!known) {
    check_block_crc(file, block, index);
    if (framed) {  // spec §7.1, from the header and a streamed payload CRC
      if (block.stored_size <= 32)
        throw Error(ErrorClass::Malformed,
                    part + "stored_size " + std::to_string(block.stored_size) + " leaves no room for a payload");
      const std::vector<std::uint8_t> header = file.read(block.file_offset, 32);
      check_block_header(header.data(), block.stored_size, block, part,
                         crc32c_of_range(file, block.file_offset + 32, block.stored_size - 32));
    }
    return {};
  }
  // Known streams: the index bounded stored_size by the decoded size (spec §7).
  return decode_stored_block(file.path(), block, index, width, framed, brick,
                             file.read(block.file_offset, block.stored_size));
}

std::vector<std::uint8_t> decode_stored_block(const std::string& path, const BlockInfo& block, std::size_t index,
                                              std::size_t width, bool framed, const std::optional<Dims>& brick,
                                              std::vector<std::uint8_t> stored) {
  std::vector<std::uint8_t> decoded(std::size_t{block.element_count} * width);
  decode_stored_into(path, block, index, width, framed, brick, stored.data(), stored.size(), decoded.data());
  return decoded;
}

void decode_stored_into(const std::string& path, const BlockInfo& block, std::size_t index, std::size_t width,
                        bool framed, const std::optional<Dims>& brick, const std::uint8_t* stored,
                        std::size_t stored_size, std::uint8_t* out) {
  const std::string part = block_part(path, block, index);
  const std::uint32_t actual = crc32c(stored, stored_size);
  if (actual != block.crc) throw Error(ErrorClass::Checksum, part + crc_text(actual, block.crc));
  if (framed) {  // spec §7.1: the block header repeats the index entry; the payload follows it
    check_block_header(stored, stored_size, block, part);
    stored += 32;
    stored_size -= 32;
  }
  const std::size_t decoded_size = std::size_t{block.element_count} * width;
  if (block.codec == 0) {  // the index checked the size (spec §7)
    if (stored_size != decoded_size)
      throw Error(ErrorClass::Malformed, part + "codec 0 stores " + std::to_string(stored_size) + " bytes, not " +
                                             std::to_string(decoded_size));
    std::memcpy(out, stored, decoded_size);
    return;
  }
  if (block.codec == 3) {  // spec §7.2: a brick of 16-bit values
    if (!brick || width != 2 || std::uint64_t{(*brick)[0]} * (*brick)[1] * (*brick)[2] != block.element_count)
      throw Error(ErrorClass::Malformed,
                  part + "codec 3 is only for a values block holding one brick of 16-bit values");
    std::vector<std::uint16_t> values(block.element_count);
    try {
      decode_predicted(stored, stored_size, *brick, values.data());
    } catch (const Error& e) {
      throw Error(e.error_class(), part + e.what());
    }
    for (std::size_t i = 0; i < values.size(); ++i) layout::store<std::uint16_t>(out + 2 * i, values[i]);
    return;
  }
  if (block.codec == 4) {  // spec §7.3: a brick (or a run of bricks) of 16-bit values, the background masked
    if (!brick || width != 2)
      throw Error(ErrorClass::Malformed, part + "codec 4 is only for a values block holding bricks of 16-bit values");
    std::vector<std::uint16_t> values(block.element_count);
    try {
      decode_masked(stored, stored_size, values.size(), values.data());
    } catch (const Error& e) {
      throw Error(e.error_class(), part + e.what());
    }
    for (std::size_t i = 0; i < values.size(); ++i) layout::store<std::uint16_t>(out + 2 * i, values[i]);
    return;
  }
  if (block.codec == 6) {  // spec §7.4: a brick of 2- or 4-byte values, the top byte in context
    if (!brick || (width != 2 && width != 4) ||
        std::uint64_t{(*brick)[0]} * (*brick)[1] * (*brick)[2] != block.element_count)
      throw Error(ErrorClass::Malformed,
                  part + "codec 6 is only for a values block holding one brick of 2- or 4-byte values");
    try {
      decode_top_byte(stored, stored_size, *brick, static_cast<unsigned>(width), out);
    } catch (const Error& e) {
      throw Error(e.error_class(), part + e.what());
    }
    return;
  }
  if (block.codec != 1 && block.codec != 2 && block.codec != 5)
    throw Error(ErrorClass::UnsupportedFeature, part + "codec " + std::to_string(block.codec) + " is not known");

  const bool planes = (block.codec == 2 || block.codec == 5) && width > 1;
  // Byte planes are decompressed into a buffer this thread keeps (up to a
  // few MiB, the size of a typical block), then regrouped into `out`: a
  // buffer allocated per block costs its page faults every time.
  constexpr std::size_t kKeptPlanes = 8u << 20;
  thread_local std::vector<std::uint8_t> kept_planes;
  std::vector<std::uint8_t> own_planes;
  std::uint8_t* target = out;
  if (planes) {
    std::vector<std::uint8_t>& buffer = decoded_size <= kKeptPlanes ? kept_planes : own_planes;
    if (buffer.size() < decoded_size) buffer.resize(decoded_size);
    target = buffer.data();
  }
  if (block.codec == 5) {
    // Spec §7, codec 5: `width` frames back to back, frame p plane p of n
    // bytes, nothing before, between or after them. (The index refused
    // codec 5 on the metadata, whose width is 1.)
    // Every frame's header and extent first, then the frames decoded: a
    // block with both kinds of defect is malformed, as the spec orders it.
    const std::size_t n = block.element_count;
    auto which = [&](std::size_t p) {
      return "zstd frame " + std::to_string(p) + " of " + std::to_string(width) + " (byte plane " + std::to_string(p) +
             ")";
    };
    std::vector<std::size_t> starts(width + 1, 0);
    for (std::size_t p = 0; p < width; ++p) {
      const std::size_t at = starts[p];
      if (at == stored_size)
        throw Error(ErrorClass::Malformed, part + "the stored bytes end before " + which(p) + ": codec 5 holds " +
                                               std::to_string(width) + " frames, one a byte plane");
      starts[p + 1] = at + zstd_frame_size(part, which(p), stored + at, stored_size - at, n);
    }
    if (starts[width] != stored_size)
      throw Error(ErrorClass::Malformed, part + std::to_string(stored_size - starts[width]) +
                                             " bytes follow the last of the " + std::to_string(width) +
                                             " zstd frames of codec 5");
    for (std::size_t p = 0; p < width; ++p)
      decode_zstd_frame(part, which(p), stored + starts[p], starts[p + 1] - starts[p], n, target + p * n);
  } else {
    const std::string which = "the stored bytes' zstd frame";
    if (zstd_frame_size(part, which, stored, stored_size, decoded_size) != stored_size)
      throw Error(ErrorClass::Malformed, part + "the stored bytes are not exactly one complete zstd frame");
    decode_zstd_frame(part, which, stored, stored_size, decoded_size, target);
  }
  if (!planes) return;
  const std::size_t n = block.element_count;
  // Element by element, the width known to the compiler, which then
  // interleaves the planes in vector registers (a plane at a time writes
  // one byte in every `width`).
  if (width == 2)
    unshuffle<2>(target, n, out);
  else if (width == 4)
    unshuffle<4>(target, n, out);
  else if (width == 8)
    unshuffle<8>(target, n, out);
  else
    for (std::size_t p = 0; p < width; ++p)
      for (std::size_t i = 0; i < n; ++i) out[i * width + p] = target[p * n + i];
}

BlockData BlockCache::find(std::size_t block) {
  const auto it = entries_.find(block);
  if (it == entries_.end()) return nullptr;
  order_.splice(order_.begin(), order_, it->second.position);
  return it->second.data;
}

std::vector<std::size_t> BlockCache::insert(std::size_t block, BlockData data) {
  std::vector<std::size_t> evicted;
  if (entries_.count(block)) return evicted;
  used_ += data->size();
  order_.push_front(block);
  entries_.emplace(block, Entry{std::move(data), order_.begin()});
  // The budget is a byte budget: a count of blocks kept whatever their size
  // let 64 blocks of 64 MiB (a few hundred bytes of zstd each) take 4 GiB.
  // The block just inserted stays, since its caller is about to use it.
  while (used_ > capacity_ && entries_.size() > 1) {
    const std::size_t victim = order_.back();
    order_.pop_back();
    used_ -= entries_[victim].data->size();
    entries_.erase(victim);
    evicted.push_back(victim);
  }
  return evicted;
}

}  // namespace ivol::detail
