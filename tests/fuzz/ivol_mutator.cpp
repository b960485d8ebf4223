#include "ivol_mutator.hpp"

#include <zstd.h>

#include <cstring>
#include <vector>

#include "ivol/crc32c.hpp"

extern "C" std::size_t LLVMFuzzerMutate(std::uint8_t* data, std::size_t size, std::size_t max_size);

namespace ivol::fuzz {
namespace {

template <typename T>
T get(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename T>
void put(std::uint8_t* p, T v) {
  std::memcpy(p, &v, sizeof v);
}

constexpr std::size_t kHeaderMin = 40, kFooter = 32, kBlockHeader = 32;

bool framed(const std::uint8_t* f) { return (get<std::uint64_t>(f + 16) & 1u) != 0; }

// Where the index and its block table are, when the footer and the fixed
// part make sense.
struct IndexView {
  std::uint64_t offset = 0, size = 0, table = 0;
  std::uint32_t count = 0, entry = 0;
};

// The index's place, from the footer, when it lies within the file.
bool find_index_bytes(const std::uint8_t* f, std::size_t size, IndexView& v) {
  if (size < kHeaderMin + kFooter) return false;
  const std::uint8_t* footer = f + size - kFooter;
  v.offset = get<std::uint64_t>(footer);
  v.size = get<std::uint64_t>(footer + 8);
  return v.offset < size && v.size <= size - v.offset && v.size >= 48;
}

bool find_index(const std::uint8_t* f, std::size_t size, IndexView& v) {
  if (!find_index_bytes(f, size, v)) return false;
  const std::uint8_t* index = f + v.offset;
  const std::uint32_t fixed = get<std::uint32_t>(index + 4);
  v.count = get<std::uint32_t>(index + 40);
  v.entry = get<std::uint32_t>(index + 44);
  v.table = std::uint64_t{fixed} + 8ull * (index[10] + 1);
  return fixed >= 48 && v.entry >= 32 && v.entry <= 4096 && v.table <= v.size &&
         v.count <= (v.size - v.table) / v.entry;
}

// A framed block's header from its index entry, with the payload's CRC.
void reseal_block_header(std::uint8_t* block, const std::uint8_t* entry, std::uint32_t stored) {
  std::memcpy(block, "IVBK", 4);
  block[4] = entry[28];  // stream
  block[5] = entry[29];  // codec
  block[6] = entry[30];  // flags
  block[7] = entry[31];  // level
  put(block + 8, get<std::uint64_t>(entry + 8));
  put(block + 16, get<std::uint32_t>(entry + 16));
  put<std::uint32_t>(block + 20, stored - kBlockHeader);
  put(block + 24, crc32c(block + kBlockHeader, stored - kBlockHeader));
  put(block + 28, crc32c(block, 28));
}

// The decoded elements of a stream are this wide (§6.4); unknown streams as 4.
std::size_t stream_width(std::uint8_t stream, std::uint8_t value_encoding) {
  switch (stream) {
    case 1:
    case 6:
      return 1;
    case 2:
    case 5:
      return 8;
    case 3:
      return value_encoding == 3 ? 4 : 2;
    default:
      return 4;
  }
}

}  // namespace

void reseal(std::uint8_t* f, std::size_t size) {
  if (size < kHeaderMin + kFooter) return;
  const std::uint32_t header_size = get<std::uint32_t>(f + 12);
  const bool header_ok = header_size >= kHeaderMin && header_size <= size - kFooter;
  IndexView v;
  if (find_index_bytes(f, size, v)) {
    std::uint8_t* index = f + v.offset;
    const bool with_frames = header_ok && framed(f);
    // Without a block table that makes sense (a mutated depth moves it),
    // the index's own CRC is still made right.
    if (!find_index(f, size, v)) v.count = 0;
    for (std::uint32_t b = 0; b < v.count; ++b) {
      std::uint8_t* e = index + v.table + std::uint64_t{b} * v.entry;
      const std::uint64_t at = get<std::uint64_t>(e);
      const std::uint32_t stored = get<std::uint32_t>(e + 20);
      if (at >= size || stored > size - at) continue;
      // The block may overlap the index when its offsets are mutated: its
      // header is then not rewritten (that would change the index).
      if (with_frames && stored > kBlockHeader && at >= header_size && at + stored <= v.offset)
        reseal_block_header(f + at, e, stored);
      if (at + stored <= v.offset || at >= v.offset + v.size) put(e + 24, crc32c(f + at, stored));
    }
    // The volume descriptor repeats the fixed part's bytes 8 .. 40.
    if (header_ok && framed(f) && header_size >= 80 && v.offset >= 80) std::memcpy(f + 36, index + 8, 32);
    put(f + size - kFooter + 16, crc32c(index, v.size));
  }
  if (header_ok) put(f + header_size - 4, crc32c(f, header_size - 4));
  put(f + size - kFooter + 20, crc32c(f + size - kFooter, 20));
}

std::size_t mutate_decoded_block(std::uint8_t* f, std::size_t size, std::size_t max_size, unsigned seed) {
  IndexView v;
  if (!find_index(f, size, v) || v.count == 0) return 0;
  const std::uint32_t header_size = get<std::uint32_t>(f + 12);
  if (header_size < kHeaderMin || v.offset < header_size || v.size != size - kFooter - v.offset) return 0;
  const std::uint8_t* index = f + v.offset;
  const std::size_t frame = framed(f) ? kBlockHeader : 0;
  // Every other seed: the metadata or a node block when there is one, where
  // the reader's structural checks are.
  std::uint32_t b = (seed >> 3) % v.count;
  if (seed & 4u)
    for (std::uint32_t k = 0; k < v.count; ++k) {
      const std::uint32_t c = (b + k) % v.count;
      const std::uint8_t stream = index[v.table + std::uint64_t{c} * v.entry + 28];
      if (stream == 1 || stream == 2 || stream == 5 || stream == 6) {
        b = c;
        break;
      }
    }
  const std::uint8_t* e = index + v.table + std::uint64_t{b} * v.entry;
  const std::uint64_t at = get<std::uint64_t>(e);
  const std::uint32_t stored = get<std::uint32_t>(e + 20);
  const std::uint32_t elements = get<std::uint32_t>(e + 16);
  const std::uint8_t stream = e[28], codec = e[29];
  if (at < header_size || at > v.offset || stored > v.offset - at || stored <= frame || codec > 5) return 0;
  const std::size_t width = stream_width(stream, index[9]);
  std::uint64_t decoded_size = std::uint64_t{elements} * width;
  if (decoded_size == 0 || decoded_size > (1u << 20)) return 0;
  const std::uint8_t* payload = f + at + frame;
  const std::uint32_t payload_size = stored - static_cast<std::uint32_t>(frame);
  // Codecs 3 and 4 (spec §7.2, §7.3): a codec header, then one zstd frame
  // of residuals or of a mask and values. The header is kept (or, for a
  // constant brick of codec 4, which is only a header, mutated itself); the
  // frame's content is mutated, any length: the reader must check it against
  // the header and the element count, which stays.
  const std::size_t codec_header = codec == 3 ? 24 : codec == 4 ? 4 : 0;
  if (payload_size < codec_header) return 0;
  if (codec == 4 && payload_size == codec_header) {
    std::vector<std::uint8_t> header(payload, payload + codec_header);
    LLVMFuzzerMutate(header.data(), codec_header, codec_header);
    std::memcpy(f + at + frame, header.data(), codec_header);
    reseal(f, size);
    return size;
  }
  if (codec == 3 || codec == 4) {
    const unsigned long long content_size =
        ZSTD_getFrameContentSize(payload + codec_header, payload_size - codec_header);
    if (content_size == ZSTD_CONTENTSIZE_ERROR || content_size == ZSTD_CONTENTSIZE_UNKNOWN || content_size == 0 ||
        content_size > (2u << 20))
      return 0;
    decoded_size = content_size;
  }
  // Codec 2's content is the byte planes: mutating them is as good as
  // mutating the elements, and it is encoded back as it was.
  std::vector<std::uint8_t> content(decoded_size + 256);
  if (codec == 0) {
    if (payload_size != decoded_size) return 0;
    std::memcpy(content.data(), payload, payload_size);
  } else if (codec == 5) {
    // A frame a byte plane (spec §7): the planes, one after the other, are
    // codec 2's content, mutated alike and encoded back a frame each.
    if (width < 2) return 0;
    std::size_t at_frame = 0;
    for (std::size_t p = 0; p < width; ++p) {
      const std::size_t frame_size = ZSTD_findFrameCompressedSize(payload + at_frame, payload_size - at_frame);
      if (ZSTD_isError(frame_size)) return 0;
      const std::size_t got = ZSTD_decompress(content.data() + p * elements, elements, payload + at_frame, frame_size);
      if (ZSTD_isError(got) || got != elements) return 0;
      at_frame += frame_size;
    }
  } else {
    const std::size_t got =
        ZSTD_decompress(content.data(), decoded_size, payload + codec_header, payload_size - codec_header);
    if (ZSTD_isError(got) || got != decoded_size) return 0;
  }
  // Elements stay whole: the mutated size is a multiple of the width (the
  // metadata, of width 1, may grow or shrink).
  std::size_t n = LLVMFuzzerMutate(content.data(), decoded_size, content.size());
  if (codec < 3 || codec == 5) n -= n % width;
  if (n == 0) return 0;
  std::vector<std::uint8_t> encoded(frame);
  encoded.insert(encoded.end(), payload, payload + codec_header);
  if (codec == 0) {
    encoded.insert(encoded.end(), content.begin(), content.begin() + static_cast<std::ptrdiff_t>(n));
  } else if (codec == 5) {
    const std::size_t plane = n / width;
    for (std::size_t p = 0; p < width; ++p) {
      const std::size_t before = encoded.size();
      encoded.resize(before + ZSTD_compressBound(plane));
      const std::size_t z =
          ZSTD_compress(encoded.data() + before, encoded.size() - before, content.data() + p * plane, plane, 1);
      if (ZSTD_isError(z)) return 0;
      encoded.resize(before + z);
    }
  } else {
    const std::size_t before = encoded.size();
    encoded.resize(before + ZSTD_compressBound(n));
    const std::size_t z = ZSTD_compress(encoded.data() + before, encoded.size() - before, content.data(), n, 1);
    if (ZSTD_isError(z)) return 0;
    encoded.resize(before + z);
  }
  if (frame) std::memcpy(encoded.data(), f + at, frame);  // resealed below
  const std::int64_t delta = static_cast<std::int64_t>(encoded.size()) - stored;
  if (static_cast<std::int64_t>(size) + delta > static_cast<std::int64_t>(max_size)) return 0;
  std::vector<std::uint8_t> out(f, f + at);
  out.insert(out.end(), encoded.begin(), encoded.end());
  out.insert(out.end(), f + at + stored, f + size);
  std::uint8_t* new_index = out.data() + v.offset + delta;
  for (std::uint32_t k = 0; k < v.count; ++k) {
    std::uint8_t* ek = new_index + v.table + std::uint64_t{k} * v.entry;
    if (k == b) {
      if (codec < 3 || codec == 5) put<std::uint32_t>(ek + 16, static_cast<std::uint32_t>(n / width));
      put<std::uint32_t>(ek + 20, static_cast<std::uint32_t>(encoded.size()));
    } else if (get<std::uint64_t>(ek) > at) {
      put<std::uint64_t>(ek, get<std::uint64_t>(ek) + delta);
    }
  }
  put<std::uint64_t>(out.data() + out.size() - kFooter, v.offset + delta);
  std::memcpy(f, out.data(), out.size());
  reseal(f, out.size());
  return out.size();
}

std::size_t mutate_index_field(std::uint8_t* f, std::size_t size, unsigned seed) {
  IndexView v;
  if (!find_index(f, size, v)) return 0;
  std::uint8_t* index = f + v.offset;
  // Values at and around the limits the reader must check.
  static const std::uint64_t kNear[] = {
      0, 1, 2, 7, 8, 9, 31, 32, 33, 0x7fffffff, 0x80000000, 0xffffffff, 1ull << 56, 1ull << 60, ~0ull >> 1, ~0ull};
  const std::uint64_t value = kNear[(seed >> 8) % (sizeof kNear / sizeof kNear[0])];
  const unsigned depth = index[10];
  switch ((seed >> 3) % 5) {
    case 0:  // depth, cell_log2 or a size of the fixed part
      if ((seed >> 12) & 1u)
        index[10 + (seed >> 13) % 2] = static_cast<std::uint8_t>(value);
      else
        put<std::uint32_t>(index + 12 + 4 * ((seed >> 13) % 3), static_cast<std::uint32_t>(value));
      break;
    case 1:  // a level's inner-node count
      put<std::uint64_t>(index + get<std::uint32_t>(index + 4) + 8 * ((seed >> 13) % (depth + 1)), value);
      break;
    default: {  // a block entry's first_element, element_count, level, stream or flags
      if (v.count == 0) return 0;
      std::uint8_t* e = index + v.table + std::uint64_t{(seed >> 13) % v.count} * v.entry;
      switch ((seed >> 20) % 5) {
        case 0:
          put<std::uint64_t>(e + 8, value);
          break;
        case 1:
          put<std::uint32_t>(e + 16, static_cast<std::uint32_t>(value));
          break;
        default: {
          static const int kByteFields[] = {28, 30, 31};  // stream, flags, level
          e[kByteFields[(seed >> 20) % 5 - 2]] = static_cast<std::uint8_t>(value);
          break;
        }
      }
    }
  }
  reseal(f, size);
  return size;
}

}  // namespace ivol::fuzz
