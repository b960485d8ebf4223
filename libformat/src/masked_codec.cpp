// Codec 4, masked 16-bit (spec §7.3).
#include "ivol/masked_codec.hpp"

#include <zstd.h>
#include <zstd_errors.h>

#include <cstring>
#include <memory>
#include <string>

#include "ivol/error.hpp"
#include "zstd_parts.hpp"

namespace ivol {
namespace {

constexpr std::uint8_t kFormConstant = 0;  // every value is the background; no frame
constexpr std::uint8_t kFormMasked = 1;    // the mask and the other values in one zstd frame

std::size_t mask_bytes(std::size_t count) { return (count + 7) / 8; }

[[noreturn]] void bad(const std::string& what) { throw Error(ErrorClass::Malformed, "codec 4: " + what); }

// A counter per 16-bit pattern, kept per thread (one table for both
// functions below) and reset only where it was used.
std::vector<std::uint32_t>& value_counts() {
  thread_local std::vector<std::uint32_t> counts(65536, 0);
  return counts;
}

}  // namespace

CommonValue most_common_value(const std::uint16_t* values, std::size_t count) {
  // A counter per pattern, kept per thread and reset only where it was used,
  // so a brick costs one pass over its values, not over 65536 counters.
  // Runs of one value are counted first and added at once: a counter
  // incremented voxel after voxel waits on its own last store, and a brick
  // of air is one long run.
  std::vector<std::uint32_t>& counts = value_counts();
  CommonValue best{values[0], 0};
  auto add = [&](std::uint16_t value, std::uint32_t run) {
    const std::uint32_t c = counts[value] += run;
    if (c > best.count || (c == best.count && value < best.value)) best = {value, c};
  };
  std::uint16_t run_value = values[0];
  std::uint32_t run = 0;
  for (std::size_t i = 0; i < count; ++i) {
    if (values[i] == run_value) {
      ++run;
      continue;
    }
    add(run_value, run);
    run_value = values[i], run = 1;
  }
  add(run_value, run);
  for (std::size_t i = 0; i < count; ++i) counts[values[i]] = 0;
  return best;
}

// Counting every value (most_common_value) was a twentieth of a noisy
// binary16 conversion's time, though a noisy brick repeats no value that
// often. So the values of every 127th voxel (a stride coprime with a
// brick's power-of-two rows, so that x, y and z all vary) are counted
// first, and only a value that fills a sixteenth of that sample, half the
// share codec 4 asks for, is counted over the brick.
CommonValue likely_background(const std::uint16_t* values, std::size_t n) {
  constexpr std::size_t kStride = 127, kSampleAtLeast = 64;
  if (n < kStride * kSampleAtLeast) return most_common_value(values, n);
  std::vector<std::uint32_t>& counts = value_counts();
  std::size_t samples = 0;
  std::uint16_t candidate = 0;
  std::uint32_t candidate_count = 0;
  for (std::size_t i = 0; i < n; i += kStride, ++samples) {
    const std::uint32_t c = ++counts[values[i]];
    if (c > candidate_count) candidate = values[i], candidate_count = c;
  }
  for (std::size_t i = 0; i < n; i += kStride) counts[values[i]] = 0;
  if (16 * std::size_t{candidate_count} < samples) return CommonValue{values[0], 0};
  // The sample's most common value, counted over the brick (a loop that
  // vectorises); only it can be the background the sample shows.
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) count += values[i] == candidate;
  return CommonValue{candidate, count};
}

std::uint64_t masked_payload_bound(std::uint64_t count) {
  return kMaskedHeaderSize + ZSTD_compressBound(static_cast<std::size_t>(mask_bytes(count) + 2 * count));
}

std::vector<std::uint8_t> encode_masked(const std::uint16_t* values, std::size_t count, std::uint16_t background,
                                        int zstd_level) {
  if (count == 0) throw Error(ErrorClass::InvalidArgument, "encode_masked: no values");
  std::vector<std::uint8_t> out(kMaskedHeaderSize);
  out[0] = static_cast<std::uint8_t>(background);
  out[1] = static_cast<std::uint8_t>(background >> 8);
  out[3] = 0;  // reserved
  const std::size_t m = mask_bytes(count);
  std::size_t others = 0;
  for (std::size_t i = 0; i < count; ++i) others += values[i] != background;
  if (others == 0) {
    out[2] = kFormConstant;
    return out;
  }
  out[2] = kFormMasked;
  std::vector<std::uint8_t> content(m + 2 * others, 0);
  std::uint8_t* lo = content.data() + m;
  std::uint8_t* hi = lo + others;
  for (std::size_t i = 0, k = 0; i < count; ++i) {
    if (values[i] == background) {
      content[i / 8] = static_cast<std::uint8_t>(content[i / 8] | 1u << (i % 8));
      continue;
    }
    lo[k] = static_cast<std::uint8_t>(values[i]);
    hi[k++] = static_cast<std::uint8_t>(values[i] >> 8);
  }
  thread_local std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!context) throw Error(ErrorClass::Io, "zstd: cannot create a compression context");
  ZSTD_CCtx_reset(context.get(), ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_compressionLevel, zstd_level);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_contentSizeFlag, 1);
  detail::compress_parts(context.get(), {{content.data(), m}, {lo, others}, {hi, others}}, out, kMaskedHeaderSize);
  return out;
}

void decode_masked(const std::uint8_t* payload, std::size_t size, std::size_t count, std::uint16_t* out) {
  if (size < kMaskedHeaderSize)
    bad("the payload of " + std::to_string(size) + " bytes is shorter than the codec header");
  const auto background = static_cast<std::uint16_t>(payload[0] | payload[1] << 8);
  if (payload[3] != 0) bad("the reserved byte 3 is not 0");
  if (payload[2] == kFormConstant) {
    if (size != kMaskedHeaderSize)
      bad("a constant brick (form 0) has a payload of exactly 4 bytes, not " + std::to_string(size));
    for (std::size_t i = 0; i < count; ++i) out[i] = background;
    return;
  }
  if (payload[2] != kFormMasked) bad("form " + std::to_string(payload[2]) + " is not 0 or 1");

  const std::uint8_t* frame = payload + kMaskedHeaderSize;
  const std::size_t frame_size = size - kMaskedHeaderSize;
  static constexpr unsigned char kMagic[4] = {0x28, 0xB5, 0x2F, 0xFD};
  if (frame_size < 4 || std::memcmp(frame, kMagic, 4) != 0)
    bad("the bytes after the codec header are not a zstd frame");
  const unsigned long long content_size = ZSTD_getFrameContentSize(frame, frame_size);
  if (content_size == ZSTD_CONTENTSIZE_UNKNOWN) bad("the zstd frame does not carry Frame_Content_Size");
  if (content_size == ZSTD_CONTENTSIZE_ERROR) bad("the zstd frame header is invalid");
  const std::size_t m = mask_bytes(count);
  // The mask and every other value: checked before anything is allocated.
  if (content_size < m || content_size > m + 2 * std::uint64_t{count} || (content_size - m) % 2 != 0)
    bad("the zstd frame holds " + std::to_string(content_size) + " bytes, not the " + std::to_string(m) +
        "-byte mask and two bytes per value that is not the background");
  if (ZSTD_getDictID_fromFrame(frame, frame_size) != 0) bad("the zstd frame needs a dictionary");
  const std::size_t whole = ZSTD_findFrameCompressedSize(frame, frame_size);
  if (ZSTD_isError(whole) || whole != frame_size)
    bad("the bytes after the codec header are not exactly one complete zstd frame");

  std::vector<std::uint8_t> content(static_cast<std::size_t>(content_size));
  ZSTD_DCtx* const context = detail::thread_decompression_context();
  const std::size_t got = ZSTD_decompressDCtx(context, content.data(), content.size(), frame, frame_size);
  if (ZSTD_isError(got)) {
    if (ZSTD_getErrorCode(got) == ZSTD_error_checksum_wrong)
      throw Error(ErrorClass::Checksum, "codec 4: the zstd content checksum does not match");
    bad(std::string("zstd cannot decode the frame: ") + ZSTD_getErrorName(got));
  }
  if (got != content.size())
    bad("the frame decoded to " + std::to_string(got) + " bytes, its header says " + std::to_string(content.size()));
  if (count % 8 != 0 && (content[m - 1] >> (count % 8)) != 0) bad("mask bits past the last value are set");
  std::size_t others = 0;
  for (std::size_t i = 0; i < count; ++i) others += !(content[i / 8] >> (i % 8) & 1);
  if (content.size() != m + 2 * others)
    bad("the mask leaves " + std::to_string(others) + " values that are not the background, the frame holds " +
        std::to_string((content.size() - m) / 2));
  const std::uint8_t* lo = content.data() + m;
  const std::uint8_t* hi = lo + others;
  for (std::size_t i = 0, k = 0; i < count; ++i) {
    if (content[i / 8] >> (i % 8) & 1) {
      out[i] = background;
      continue;
    }
    out[i] = static_cast<std::uint16_t>(lo[k] | hi[k] << 8);
    ++k;
  }
}

}  // namespace ivol
