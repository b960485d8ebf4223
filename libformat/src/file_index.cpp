#include "file_index.hpp"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "block_reader.hpp"
#include "brick_grid.hpp"
#include "framing.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/masked_codec.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/top_byte_codec.hpp"
#include "layout.hpp"

namespace ivol {

const char* stream_name(std::uint8_t stream) {
  switch (stream) {
    case 1:
      return "metadata";
    case 2:
      return "nodes";
    case 3:
      return "values";
    case 4:
      return "borders";
    case 5:
      return "cells";
    case 7:
      return "stored level";
    default:
      return "unknown stream";
  }
}

namespace detail {
namespace {

using layout::load;

// Over HTTP the open fetches the footer with this much before it (a small
// index comes along), and a larger index exactly when it is at most
// kIndexPrefetchMost; pages of 64 KiB at each end were 6 % of a 2 MB file.
constexpr std::uint64_t kIndexGuess = 16 * 1024;
constexpr std::uint64_t kIndexPrefetchMost = 16u << 20;

const char* kind_name(StructureKind kind) {
  switch (kind) {
    case StructureKind::Octree:
      return "octree";
    case StructureKind::Regular:
      return "regular grid";
    case StructureKind::Rectilinear:
      return "rectilinear grid";
    case StructureKind::Nested:
      return "nested grid";
    case StructureKind::Bricked:
      return "bricked regular grid";
  }
  return "?";
}

std::string hex32(std::uint32_t v) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%08X", v);
  return text;
}

class StructureReader {
 public:
  explicit StructureReader(RandomAccessFile& file) : file_(file) {}

  FileInfo run() {
    info_.file_size = file_.size();
    read_header();
    read_footer();
    read_index();
    return info_;
  }

 private:
  [[noreturn]] void fail(ErrorClass c, const std::string& part, const std::string& what) const {
    throw Error(c, file_.path() + ": " + part + ": " + what);
  }

  void read_header() {
    const std::uint64_t size = file_.size();
    // The first 16 bytes say how long the header is; read no more until then.
    header_ = file_.read(0, static_cast<std::size_t>(std::min<std::uint64_t>(size, 16)));
    const std::size_t prefix = header_.size();
    const std::size_t sig_bytes = std::min<std::size_t>(prefix, 8);
    if (sig_bytes > 0 && std::memcmp(header_.data(), layout::kSignature.data(), sig_bytes) != 0)
      fail(ErrorClass::NotIvol, "header", "the file does not start with the .ivol signature 89 49 56 4F 4C 0D 0A 0A");
    if (size < 10) fail(ErrorClass::Truncated, "header", "the file is only " + std::to_string(size) + " bytes long");
    info_.version_major = load<std::uint16_t>(&header_[layout::kHeaderVersionMajor]);
    if (info_.version_major != layout::kVersionMajor)
      fail(ErrorClass::UnsupportedVersion, "header",
           "format version " + std::to_string(info_.version_major) +
               ".x is not supported (this reader reads major version 1)");
    if (size < 16) fail(ErrorClass::Truncated, "header", "the file ends inside the header");
    info_.version_minor = load<std::uint16_t>(&header_[layout::kHeaderVersionMinor]);
    info_.header_size = load<std::uint32_t>(&header_[layout::kHeaderSizeField]);
    if (info_.header_size < layout::kHeaderSize || info_.header_size > layout::kMaxHeaderSize)
      fail(ErrorClass::Malformed, "header",
           "header_size " + std::to_string(info_.header_size) + " is outside 40 .. 4096");
    if (size < std::uint64_t{info_.header_size} + layout::kFooterSize)
      fail(ErrorClass::Truncated, "header",
           "the file (" + std::to_string(size) + " bytes) is shorter than its header and a footer");
    header_ = file_.read(0, info_.header_size);
    const std::uint32_t stored = load<std::uint32_t>(&header_[info_.header_size - 4]);
    const std::uint32_t actual = crc32c(header_.data(), info_.header_size - 4);
    if (stored != actual)
      fail(ErrorClass::Checksum, "header", "CRC-32C is " + hex32(actual) + " but header_crc says " + hex32(stored));
    if (load<std::uint32_t>(&header_[layout::kHeaderReserved]) != 0)
      fail(ErrorClass::Malformed, "header", "reserved bytes 32..35 are not zero");
    info_.required_features = load<std::uint64_t>(&header_[layout::kHeaderRequiredFeatures]);
    info_.optional_features = load<std::uint64_t>(&header_[layout::kHeaderOptionalFeatures]);
    const std::uint64_t unknown = info_.required_features & ~layout::kFeatureFramedBlocks;
    if (unknown != 0) {
      std::string bits;
      for (int b = 0; b < 64; ++b)
        if ((unknown >> b) & 1u) bits += (bits.empty() ? "" : ", ") + std::to_string(b);
      fail(ErrorClass::UnsupportedFeature, "header",
           "required feature bit(s) " + bits + " are not known to this reader");
    }
    if (info_.framed()) {  // spec §4: the volume descriptor, checked against the index later
      if (info_.header_size < layout::kFramedHeaderSize)
        fail(ErrorClass::Malformed, "header",
             "header_size " + std::to_string(info_.header_size) +
                 " is below 80, but required feature bit 0 (framed_blocks) needs the volume descriptor");
      for (std::size_t i = layout::kHeaderDescriptorReserved; i < layout::kHeaderDescriptorReserved + 8; ++i)
        if (header_[i] != 0) fail(ErrorClass::Malformed, "header", "reserved bytes 68..75 are not zero");
    }
  }

  void read_footer() {
    const std::uint64_t size = file_.size();
    // A remote file: the footer with the last few KiB, where a small index
    // lies, in one exact request instead of a page (a local file ignores it).
    const std::uint64_t tail = std::min<std::uint64_t>(size, layout::kFooterSize + kIndexGuess);
    file_.prefetch({{size - tail, tail}});
    const auto footer = file_.read(size - layout::kFooterSize, layout::kFooterSize);
    if (std::memcmp(&footer[layout::kFooterEndSignature], layout::kEndSignature.data(), 8) != 0)
      fail(ErrorClass::Truncated, "footer",
           "the file does not end with IVOL_END (truncated, extended or damaged at its end)");
    const std::uint32_t stored = load<std::uint32_t>(&footer[layout::kFooterCrc]);
    const std::uint32_t actual = crc32c(footer.data(), layout::kFooterCrc);
    if (stored != actual)
      fail(ErrorClass::Checksum, "footer", "CRC-32C is " + hex32(actual) + " but footer_crc says " + hex32(stored));
    info_.index_offset = load<std::uint64_t>(&footer[layout::kFooterIndexOffset]);
    info_.index_size = load<std::uint64_t>(&footer[layout::kFooterIndexSize]);
    index_crc_ = load<std::uint32_t>(&footer[layout::kFooterIndexCrc]);
    const std::uint64_t room = size - layout::kFooterSize;
    if (info_.index_offset < info_.header_size || info_.index_offset > room ||
        info_.index_size != room - info_.index_offset)
      fail(ErrorClass::Malformed, "footer",
           "index at offset " + std::to_string(info_.index_offset) + " with size " + std::to_string(info_.index_size) +
               " does not end where the footer begins (" + std::to_string(room) + ")");
    // The largest index the blocks before it allow: every block takes at
    // least one byte, an entry at most 4096 (spec §6). A claimed index
    // beyond it is refused before a byte of it is read.
    const std::uint64_t blocks_bytes = info_.index_offset - info_.header_size;
    const std::uint64_t fixed_most = layout::kMaxIndexFixedSize + 8ull * (layout::kMaxDepth + 1);
    // index_size > fixed_most + 4096 * blocks_bytes, without overflow.
    if (info_.index_size > fixed_most &&
        (info_.index_size - fixed_most - 1) / layout::kMaxBlockEntrySize >= blocks_bytes)
      fail(ErrorClass::Malformed, "footer",
           "index_size " + std::to_string(info_.index_size) + " exceeds what " + std::to_string(blocks_bytes) +
               " bytes of blocks allow (4352 + 4096 per byte)");
  }

  void read_index() {
    if (info_.index_size < layout::kIndexFixedSize)
      fail(ErrorClass::Malformed, "index", "index_size " + std::to_string(info_.index_size) + " is smaller than 48");
    // The CRC first, a chunk at a time; then the fixed part and the level
    // table, and the block table entry by entry: what is held is bounded by
    // the entries the index really has, not by its claimed size.
    // A remote file: a larger index in one request, with the kIndexGuess
    // bytes before it, where a writer that learns the metadata last puts it
    // (and the last, small blocks a read would otherwise fetch one by one);
    // a claimed size beyond kIndexPrefetchMost goes by pages, as read.
    // (An index of at most kIndexGuess came with the footer.)
    if (info_.index_size > kIndexGuess && info_.index_size <= kIndexPrefetchMost) {
      const std::uint64_t from = std::max<std::uint64_t>(
          info_.header_size, info_.index_offset - std::min<std::uint64_t>(info_.index_offset, kIndexGuess));
      file_.prefetch({{from, info_.index_offset + info_.index_size - from}});
    }
    const std::uint32_t actual = crc32c_of_range(file_, info_.index_offset, info_.index_size);
    if (actual != index_crc_)
      fail(ErrorClass::Checksum, "index",
           "CRC-32C is " + hex32(actual) + " but the footer's index_crc says " + hex32(index_crc_));
    const auto head = file_.read(info_.index_offset, layout::kIndexFixedSize);
    if (std::memcmp(head.data(), layout::kIndexSignature.data(), 4) != 0)
      fail(ErrorClass::Malformed, "index", "does not start with IVIX");
    const std::uint32_t fixed_size = load<std::uint32_t>(head.data() + layout::kIndexFixedSizeField);
    if (fixed_size < layout::kIndexFixedSize || fixed_size > layout::kMaxIndexFixedSize ||
        fixed_size > info_.index_size)
      fail(ErrorClass::Malformed, "index",
           "fixed_size " + std::to_string(fixed_size) + " is outside 48 .. 4096 or the index");
    const auto fixed = file_.read(info_.index_offset, fixed_size);
    const unsigned char* p = fixed.data();
    const std::uint8_t structure = p[layout::kIndexStructureKind];
    if (structure < 1 || structure > 5)
      fail(ErrorClass::UnsupportedFeature, "index",
           "structure_kind " + std::to_string(structure) +
               " is not known (1 = octree, 2 = regular, 3 = rectilinear, 4 = nested, 5 = bricked)");
    const std::uint8_t encoding = p[layout::kIndexValueEncoding];
    if (!is_known_encoding(encoding))
      fail(ErrorClass::UnsupportedFeature, "index", "value_encoding " + std::to_string(encoding) + " is not known");
    VolumeLayout& v = info_.layout;
    v.kind = static_cast<StructureKind>(structure);
    v.encoding = static_cast<ValueEncoding>(encoding);
    v.depth = p[layout::kIndexDepth];
    v.cell_log2 = p[layout::kIndexCellLog2];
    if (v.kind == StructureKind::Nested && (v.cell_log2 < 1 || v.cell_log2 > 31))
      fail(ErrorClass::Malformed, "index", "cell_log2 " + std::to_string(v.cell_log2) + " is outside 1 .. 31");
    if (v.kind == StructureKind::Bricked && !info_.framed())
      fail(ErrorClass::Malformed, "index",
           "a bricked regular grid (structure_kind 5) needs framed blocks (format 1.3)");
    if (v.kind == StructureKind::Bricked && (v.cell_log2 < 1 || v.cell_log2 > layout::kMaxBrickLog2))
      fail(ErrorClass::Malformed, "index",
           "brick_log2 (byte 11) " + std::to_string(v.cell_log2) + " is outside 1 .. " +
               std::to_string(layout::kMaxBrickLog2));
    if (v.kind != StructureKind::Nested && v.kind != StructureKind::Bricked && v.cell_log2 != 0)
      fail(ErrorClass::Malformed, "index", "reserved byte 11 is not zero");
    for (int a = 0; a < 3; ++a) {
      v.dims[a] = load<std::uint32_t>(p + layout::kIndexSizeX + 4 * a);
      if (v.dims[a] == 0) fail(ErrorClass::Malformed, "index", std::string("size_") + "xyz"[a] + " is 0");
    }
    if (v.depth > layout::kMaxDepth || v.depth != depth_for(v.dims))
      fail(ErrorClass::Malformed, "index",
           "depth " + std::to_string(v.depth) +
               " is not the smallest D with 2^D >= " + std::to_string(std::max({v.dims[0], v.dims[1], v.dims[2]})));
    v.value_scale = load<double>(p + layout::kIndexScale);
    v.value_offset = load<double>(p + layout::kIndexOffset);
    if (!std::isfinite(v.value_scale) || v.value_scale == 0.0)
      fail(ErrorClass::Malformed, "index", "value_scale is not finite and non-zero");
    if (!std::isfinite(v.value_offset)) fail(ErrorClass::Malformed, "index", "value_offset is not finite");
    const std::uint32_t block_count = load<std::uint32_t>(p + layout::kIndexBlockCount);
    const std::uint32_t entry_size = load<std::uint32_t>(p + layout::kIndexBlockEntrySize);
    if (block_count < 2)
      fail(ErrorClass::Malformed, "index", "block_count " + std::to_string(block_count) + " is below 2");
    if (entry_size < layout::kBlockEntrySize || entry_size > layout::kMaxBlockEntrySize)
      fail(ErrorClass::Malformed, "index", "block_entry_size " + std::to_string(entry_size) + " is outside 32 .. 4096");
    const std::uint64_t expected =
        std::uint64_t{fixed_size} + 8ull * (v.depth + 1) + std::uint64_t{block_count} * entry_size;
    if (expected != info_.index_size)
      fail(ErrorClass::Malformed, "index",
           "index_size is " + std::to_string(info_.index_size) + " but its fields need " + std::to_string(expected));
    if (info_.framed() &&
        std::memcmp(p + layout::kIndexStructureKind, &header_[layout::kHeaderDescriptor], layout::kDescriptorSize) != 0)
      fail(ErrorClass::Malformed, "header",
           "the volume descriptor (bytes 36..67) differs from the index's fixed part (bytes 8..39)");
    const auto levels = file_.read(info_.index_offset + fixed_size, 8ull * (v.depth + 1));
    read_level_table(levels.data());
    read_block_table(info_.index_offset + fixed_size + 8ull * (v.depth + 1), block_count, entry_size);
  }

  void read_level_table(const unsigned char* p) {
    VolumeLayout& v = info_.layout;
    v.inner_count.resize(v.depth + 1);
    for (unsigned l = 0; l <= v.depth; ++l) v.inner_count[l] = load<std::uint64_t>(p + 8 * l);
    auto bad = [&](const std::string& what) { fail(ErrorClass::Malformed, "level table", what); };
    if (v.kind != StructureKind::Octree) {
      for (unsigned l = 0; l <= v.depth; ++l)
        if (v.inner_count[l] != 0) bad("inner_count[" + std::to_string(l) + "] is not 0 for a " + kind_name(v.kind));
      return;
    }
    if (v.inner_count[0] > 1) bad("inner_count[0] is " + std::to_string(v.inner_count[0]) + ", more than one root");
    if (v.inner_count[v.depth] != 0) bad("inner_count[D] is not 0: voxels cannot be subdivided");
    // Counts are bounded before any arithmetic on them, so nothing overflows:
    // first_inner_child has 56 bits, so there are at most 2^56 inner nodes.
    constexpr std::uint64_t kMaxInner = std::uint64_t{1} << 56;
    std::uint64_t total = 0;
    for (unsigned l = 0; l <= v.depth; ++l) {
      if (v.inner_count[l] > kMaxInner || total + v.inner_count[l] > kMaxInner)
        bad("more than 2^56 inner nodes in all (inner_count[" + std::to_string(l) + "])");
      total += v.inner_count[l];
      if (l < v.depth && v.inner_count[l + 1] > 8 * v.inner_count[l])
        bad("inner_count[" + std::to_string(l + 1) + "] = " + std::to_string(v.inner_count[l + 1]) +
            " exceeds 8 x inner_count[" + std::to_string(l) + "]");
    }
  }

  void read_block_table(std::uint64_t table_offset, std::uint32_t count, std::uint32_t entry_size) {
    const VolumeLayout& v = info_.layout;
    std::uint64_t expected_offset = info_.header_size;
    std::size_t metadata_blocks = 0;
    // Entries are read 1 MiB at a time and kept only as BlockInfo: a claimed
    // block_count costs nothing until its entries pass their checks.
    const std::uint32_t per_chunk = std::max<std::uint32_t>(1, (1u << 20) / entry_size);
    std::vector<std::uint8_t> chunk;
    std::uint32_t chunk_first = 0;
    for (std::uint32_t b = 0; b < count; ++b) {
      if (b == 0 || b - chunk_first == per_chunk) {
        chunk_first = b;
        chunk = file_.read(table_offset + std::uint64_t{b} * entry_size,
                           std::size_t{std::min(per_chunk, count - b)} * entry_size);
      }
      const unsigned char* e = chunk.data() + std::size_t{b - chunk_first} * entry_size;
      BlockInfo& blk = info_.blocks.emplace_back();
      blk.file_offset = load<std::uint64_t>(e + layout::kEntryFileOffset);
      blk.first_element = load<std::uint64_t>(e + layout::kEntryFirstElement);
      blk.element_count = load<std::uint32_t>(e + layout::kEntryElementCount);
      blk.stored_size = load<std::uint32_t>(e + layout::kEntryStoredSize);
      blk.crc = load<std::uint32_t>(e + layout::kEntryCrc);
      blk.stream = e[layout::kEntryStream];
      blk.codec = e[layout::kEntryCodec];
      blk.flags = e[layout::kEntryFlags];
      blk.level = e[layout::kEntryLevel];
      const std::string part = "block table entry " + std::to_string(b);
      auto bad = [&](ErrorClass c, const std::string& what) { fail(c, part, what); };
      if (blk.file_offset != expected_offset)
        bad(ErrorClass::Malformed, "file_offset " + std::to_string(blk.file_offset) + " should be " +
                                       std::to_string(expected_offset) + " (blocks lie back to back after the header)");
      if (blk.element_count == 0) bad(ErrorClass::Malformed, "element_count is 0");
      if (blk.stored_size == 0) bad(ErrorClass::Malformed, "stored_size is 0");
      if (info_.framed() && blk.stored_size <= layout::kBlockHeaderSize)
        bad(ErrorClass::Malformed,
            "stored_size " + std::to_string(blk.stored_size) + " leaves no payload after the 32-byte block header");
      expected_offset += blk.stored_size;
      if (expected_offset > info_.index_offset)
        bad(ErrorClass::Malformed, "the block runs past the index at offset " + std::to_string(info_.index_offset));
      if (blk.flags & ~layout::kFlagIgnorable) bad(ErrorClass::Malformed, "reserved flag bits are set");
      if (!is_known_stream(blk.stream, v.kind)) {
        if (!(blk.flags & layout::kFlagIgnorable))
          bad(ErrorClass::UnsupportedFeature,
              "stream " + std::to_string(blk.stream) + " is not known and the block is not marked ignorable");
        continue;  // an ignorable block of a stream we do not know: skipped
      }
      // A stored level of detail (stream 7, spec §8A.5) is ignorable, so
      // that readers that do not know it compute the level instead.
      const bool stored_level = blk.stream == 7;
      if (stored_level && blk.flags != layout::kFlagIgnorable)
        bad(ErrorClass::Malformed, "blocks of stream 7 (stored levels of detail) must have the ignorable flag");
      if (!stored_level && blk.flags != 0) bad(ErrorClass::Malformed, "blocks of known streams must have flags 0");
      if (blk.codec > 6) bad(ErrorClass::UnsupportedFeature, "codec " + std::to_string(blk.codec) + " is not known");
      // Codecs 3 and 4 hold a brick of 16-bit values (spec §7.2, §7.3).
      if ((blk.codec == 3 || blk.codec == 4) &&
          ((blk.stream != 3 && blk.stream != 7) || v.kind != StructureKind::Bricked ||
           v.encoding == ValueEncoding::Float32))
        bad(ErrorClass::Malformed,
            "codec " + std::to_string(blk.codec) + " is only for values blocks of a bricked grid of 16-bit values");
      // Codec 6 holds a brick of 2- or 4-byte values (spec §7.4).
      if (blk.codec == 6 && ((blk.stream != 3 && blk.stream != 7) || v.kind != StructureKind::Bricked))
        bad(ErrorClass::Malformed, "codec 6 is only for values blocks of a bricked grid");
      const std::uint64_t width = stream_width(blk.stream, v.encoding);
      // Codec 5 is a frame a byte plane: for elements of more than one byte.
      if (blk.codec == 5 && width < 2)
        bad(ErrorClass::Malformed, "codec 5 (a zstd frame a byte plane) on the " +
                                       std::string(stream_name(blk.stream)) + ", whose elements are single bytes");
      const std::uint64_t decoded = blk.element_count * width;
      if (decoded > layout::kMaxBlockDecodedBytes)
        bad(ErrorClass::Malformed, "decoded size " + std::to_string(decoded) + " exceeds 64 MiB");
      const std::uint64_t frame = info_.framed() ? layout::kBlockHeaderSize : 0;
      if (blk.codec == 0 && blk.stored_size != decoded + frame)
        bad(ErrorClass::Malformed, "a stored block of " + std::to_string(blk.element_count) + " elements must be " +
                                       std::to_string(decoded + frame) + " bytes, not " +
                                       std::to_string(blk.stored_size));
      // No zstd frame of `decoded` bytes is longer than ZSTD_compressBound
      // (plus the block header in a framed file): a larger stored_size is
      // refused before the block is read (spec §7).
      if (blk.codec == 3 && blk.stored_size > predicted_payload_bound(blk.element_count) + frame)
        bad(ErrorClass::Malformed, "stored_size " + std::to_string(blk.stored_size) + " exceeds " +
                                       std::to_string(predicted_payload_bound(blk.element_count) + frame) +
                                       ", the largest codec 3 payload of " + std::to_string(blk.element_count) +
                                       " values" + (frame ? " and the block header" : ""));
      if (blk.codec == 4 && blk.stored_size > masked_payload_bound(blk.element_count) + frame)
        bad(ErrorClass::Malformed, "stored_size " + std::to_string(blk.stored_size) + " exceeds " +
                                       std::to_string(masked_payload_bound(blk.element_count) + frame) +
                                       ", the largest codec 4 payload of " + std::to_string(blk.element_count) +
                                       " values" + (frame ? " and the block header" : ""));
      if (blk.codec == 6 &&
          blk.stored_size > top_byte_payload_bound(blk.element_count, static_cast<unsigned>(width)) + frame)
        bad(ErrorClass::Malformed,
            "stored_size " + std::to_string(blk.stored_size) + " exceeds " +
                std::to_string(top_byte_payload_bound(blk.element_count, static_cast<unsigned>(width)) + frame) +
                ", the largest codec 6 payload of " + std::to_string(blk.element_count) + " values" +
                (frame ? " and the block header" : ""));
      if ((blk.codec == 1 || blk.codec == 2) && blk.stored_size > ZSTD_compressBound(decoded) + frame)
        bad(ErrorClass::Malformed, "stored_size " + std::to_string(blk.stored_size) + " exceeds " +
                                       std::to_string(ZSTD_compressBound(decoded) + frame) +
                                       ", the largest zstd frame of its " + std::to_string(decoded) + " decoded bytes" +
                                       (frame ? " and the block header" : ""));
      if (blk.codec == 5 && blk.stored_size > width * ZSTD_compressBound(blk.element_count) + frame)
        bad(ErrorClass::Malformed, "stored_size " + std::to_string(blk.stored_size) + " exceeds " +
                                       std::to_string(width * ZSTD_compressBound(blk.element_count) + frame) +
                                       ", the largest " + std::to_string(width) + " zstd frames of " +
                                       std::to_string(blk.element_count) + " bytes each" +
                                       (frame ? " and the block header" : ""));
      if (blk.level > v.depth) bad(ErrorClass::Malformed, "level " + std::to_string(blk.level) + " is deeper than D");
      std::uint64_t lo = 0;
      std::uint64_t hi = 0;
      const bool octree = v.kind == StructureKind::Octree;
      if (blk.stream == 2 && !octree)
        bad(ErrorClass::Malformed, std::string("nodes blocks do not belong in a ") + kind_name(v.kind) + " file");
      if (stored_level && (blk.level < 1 || blk.level > v.depth))
        bad(ErrorClass::Malformed, "a stored level of detail's level must be 1 .. D (" + std::to_string(v.depth) +
                                       "), not " + std::to_string(blk.level));
      if (!octree && !stored_level && blk.level != 0) bad(ErrorClass::Malformed, "level must be 0 outside octrees");
      if (blk.stream == 1) {
        ++metadata_blocks;
        if (blk.level != 0 || blk.first_element != 0)
          bad(ErrorClass::Malformed, "the metadata block must have level 0 and first_element 0");
        if (decoded > layout::kMaxMetadataBytes) bad(ErrorClass::Malformed, "metadata exceeds 16 MiB");
        continue;
      }
      if (v.kind == StructureKind::Bricked && (blk.stream == 3 || stored_level)) check_one_brick(blk, part);
      if (!octree) continue;  // ranges are checked by coverage below
      if (blk.stream == 2) {
        lo = v.first_inner(blk.level);
        hi = lo + v.inner_count[blk.level];
      } else {
        lo = v.first_value(blk.level);
        hi = lo + v.level_values(blk.level);
      }
      if (blk.first_element < lo || blk.first_element > hi || blk.element_count > hi - blk.first_element)
        bad(ErrorClass::Malformed, std::string(stream_name(blk.stream)) + " " + std::to_string(blk.first_element) +
                                       " .. " + std::to_string(blk.first_element + blk.element_count) +
                                       " do not lie in level " + std::to_string(blk.level) + "'s range " +
                                       std::to_string(lo) + " .. " + std::to_string(hi));
    }
    if (expected_offset != info_.index_offset)
      fail(ErrorClass::Malformed, "block table",
           "blocks end at " + std::to_string(expected_offset) + " but the index begins at " +
               std::to_string(info_.index_offset));
    if (metadata_blocks != 1)
      fail(ErrorClass::Malformed, "block table",
           std::to_string(metadata_blocks) + " metadata blocks (exactly 1 required)");
    switch (v.kind) {
      case StructureKind::Octree:
        check_coverage(2, v.total_inner());
        check_coverage(3, v.total_values());
        break;
      case StructureKind::Regular:
      case StructureKind::Bricked: {
        // Sizes up to 2^31 per axis: bound the product as it grows (spec §8A).
        constexpr std::uint64_t kMaxValues = std::uint64_t{1} << 56;
        std::uint64_t total = 1;
        for (int a = 0; a < 3; ++a) {
          if (total > kMaxValues / v.dims[a])
            fail(ErrorClass::Malformed, "index", "a regular grid of more than 2^56 voxels");
          total *= v.dims[a];
        }
        check_coverage(3, total);
        if (v.kind == StructureKind::Bricked) check_stored_levels();
        break;
      }
      case StructureKind::Rectilinear: {
        const std::uint64_t borders = check_coverage(4, kAnyTotal);
        if (borders == 0) fail(ErrorClass::Malformed, "block table", "a rectilinear grid needs a borders stream");
        if (borders > std::uint64_t{v.dims[0]} + v.dims[1] + v.dims[2] + 3)
          fail(ErrorClass::Malformed, "block table",
               "the borders stream holds more than size_x + size_y + size_z + 3 elements");
        check_coverage(3, kAnyTotal);
        break;
      }
      case StructureKind::Nested: {
        const std::uint64_t edge = std::uint64_t{1} << v.cell_log2;
        std::uint64_t cells = 1;
        for (int a = 0; a < 3; ++a) cells *= (v.dims[a] + edge - 1) / edge;
        check_coverage(5, cells);
        check_coverage(3, kAnyTotal);
        break;
      }
    }
  }

  // Spec §8A.4: a values block of a bricked grid holds exactly one brick,
  // or (codec 4, §7.3) a run of whole bricks that follow one another.
  // A block of stream 3 holds a brick of the volume; of stream 7, a brick
  // of its level of detail (spec §8A.5).
  void check_one_brick(const BlockInfo& blk, const std::string& part) {
    const VolumeLayout& v = info_.layout;
    const Dims dims = blk.stream == 7 ? lod_dims(v.dims, blk.level) : v.dims;
    std::uint64_t total = 1;  // more than 2^56 voxels is refused with the coverage below
    for (int a = 0; a < 3; ++a) {
      if (total > (std::uint64_t{1} << 56) / dims[a]) return;
      total *= dims[a];
    }
    const BrickGrid grid(dims, v.cell_log2);
    std::array<std::uint32_t, 3> brick{};
    if (!grid.brick_at(blk.first_element, brick))
      fail(ErrorClass::Malformed, part,
           "first_element " + std::to_string(blk.first_element) + " is not the first value of a brick");
    if (blk.codec == 4) {
      const std::uint64_t end = blk.first_element + blk.element_count;
      if (end != total && !grid.brick_at(end, brick))
        fail(ErrorClass::Malformed, part,
             "a codec 4 block ends at element " + std::to_string(end) + ", inside a brick");
      return;
    }
    const Dims e = grid.extent(brick[0], brick[1], brick[2]);
    const std::uint64_t voxels = std::uint64_t{e[0]} * e[1] * e[2];
    if (blk.element_count != voxels)
      fail(ErrorClass::Malformed, part,
           "element_count " + std::to_string(blk.element_count) + " is not the " + std::to_string(voxels) +
               " values of brick (" + std::to_string(brick[0]) + ", " + std::to_string(brick[1]) + ", " +
               std::to_string(brick[2]) + ")");
  }

  // Each stored level of detail of a bricked grid is stored whole or not at
  // all (spec §8A.5). One pass over the blocks per level that has any.
  void check_stored_levels() {
    const VolumeLayout& v = info_.layout;
    std::vector<bool> stored(v.depth + 1, false);
    for (const BlockInfo& b : info_.blocks)
      if (b.stream == 7 && b.level >= 1 && b.level <= v.depth) stored[b.level] = true;
    for (unsigned k = 1; k <= v.depth; ++k)
      if (stored[k]) check_coverage(7, voxel_count(lod_dims(v.dims, k)), static_cast<int>(k));
  }

  // Blocks of a stream (and, with level ≥ 0, of that level), in order of
  // first_element, cover 0 .. total exactly (any total with kAnyTotal: the
  // caller checks it later). Returns the total.
  static constexpr std::uint64_t kAnyTotal = ~std::uint64_t{0};
  std::uint64_t check_coverage(std::uint8_t stream, std::uint64_t total, int level = -1) {
    std::vector<const BlockInfo*> list;
    for (const auto& b : info_.blocks)
      if (b.stream == stream && (level < 0 || b.level == level)) list.push_back(&b);
    std::sort(list.begin(), list.end(),
              [](const BlockInfo* a, const BlockInfo* b) { return a->first_element < b->first_element; });
    std::uint64_t next = 0;
    for (const BlockInfo* b : list) {
      if (b->first_element != next)
        fail(ErrorClass::Malformed, "block table",
             what_stream(stream, level) + " element " + std::to_string(next) +
                 (b->first_element > next ? " is in no block" : " is in two blocks"));
      next += b->element_count;
    }
    if (total != kAnyTotal && next != total)
      fail(ErrorClass::Malformed, "block table",
           what_stream(stream, level) + ": blocks hold " + std::to_string(next) + " elements, the " +
               (level < 0 ? "structure" : "level") + " needs " + std::to_string(total));
    return next;
  }
  static std::string what_stream(std::uint8_t stream, int level) {
    return level < 0 ? std::string(stream_name(stream)) : "stored level " + std::to_string(level);
  }

  RandomAccessFile& file_;
  FileInfo info_;
  std::vector<std::uint8_t> header_;
  std::uint32_t index_crc_ = 0;
};

}  // namespace

bool is_known_stream(std::uint8_t stream) { return stream >= 1 && stream <= 5; }

bool is_known_stream(std::uint8_t stream, StructureKind kind) {
  if (stream == 4) return kind == StructureKind::Rectilinear;
  if (stream == 5) return kind == StructureKind::Nested;
  if (stream == 7) return kind == StructureKind::Bricked;
  return stream >= 1 && stream <= 3;
}

std::size_t stream_width(std::uint8_t stream, ValueEncoding encoding) {
  switch (stream) {
    case 1:
      return 1;
    case 2:
      return 8;
    case 3:
    case 7:  // a stored level of detail (spec §8A.5)
      return encoding_width(encoding);
    case 4:
      return 4;
    case 5:
      return 8;
    default:
      return 1;
  }
}

FileInfo read_file_structure(RandomAccessFile& file) { return StructureReader(file).run(); }

}  // namespace detail
}  // namespace ivol
