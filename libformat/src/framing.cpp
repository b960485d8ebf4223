#include "framing.hpp"

#include <cstdio>
#include <cstring>

#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "layout.hpp"

namespace ivol::detail {

std::array<unsigned char, 32> volume_descriptor(const VolumeLayout& v) {
  // Offsets are those of the index fixed part less 8.
  std::array<unsigned char, 32> d{};
  d[layout::kIndexStructureKind - 8] = static_cast<std::uint8_t>(v.kind);
  d[layout::kIndexValueEncoding - 8] = static_cast<std::uint8_t>(v.encoding);
  d[layout::kIndexDepth - 8] = static_cast<std::uint8_t>(v.depth);
  d[layout::kIndexCellLog2 - 8] =
      v.kind == StructureKind::Nested || v.kind == StructureKind::Bricked ? v.cell_log2 : 0;
  for (int a = 0; a < 3; ++a) layout::store<std::uint32_t>(&d[layout::kIndexSizeX - 8 + 4 * a], v.dims[a]);
  layout::store<double>(&d[layout::kIndexScale - 8], v.value_scale);
  layout::store<double>(&d[layout::kIndexOffset - 8], v.value_offset);
  return d;
}

std::array<unsigned char, 32> block_header(const BlockInfo& e, std::uint32_t payload_size, std::uint32_t payload_crc) {
  std::array<unsigned char, 32> h{};
  std::memcpy(h.data(), layout::kBlockSignature.data(), 4);
  h[layout::kBlockStream] = e.stream;
  h[layout::kBlockCodec] = e.codec;
  h[layout::kBlockFlags] = e.flags;
  h[layout::kBlockLevel] = e.level;
  layout::store<std::uint64_t>(&h[layout::kBlockFirstElement], e.first_element);
  layout::store<std::uint32_t>(&h[layout::kBlockElementCount], e.element_count);
  layout::store<std::uint32_t>(&h[layout::kBlockPayloadSize], payload_size);
  layout::store<std::uint32_t>(&h[layout::kBlockPayloadCrc], payload_crc);
  layout::store<std::uint32_t>(&h[layout::kBlockHeaderCrc], crc32c(h.data(), layout::kBlockHeaderCrc));
  return h;
}

bool parse_block_header(const unsigned char* p, BlockHeader& out) {
  if (std::memcmp(p, layout::kBlockSignature.data(), 4) != 0) return false;
  if (layout::load<std::uint32_t>(p + layout::kBlockHeaderCrc) != crc32c(p, layout::kBlockHeaderCrc)) return false;
  out.entry.stream = p[layout::kBlockStream];
  out.entry.codec = p[layout::kBlockCodec];
  out.entry.flags = p[layout::kBlockFlags];
  out.entry.level = p[layout::kBlockLevel];
  out.entry.first_element = layout::load<std::uint64_t>(p + layout::kBlockFirstElement);
  out.entry.element_count = layout::load<std::uint32_t>(p + layout::kBlockElementCount);
  out.payload_size = layout::load<std::uint32_t>(p + layout::kBlockPayloadSize);
  out.payload_crc = layout::load<std::uint32_t>(p + layout::kBlockPayloadCrc);
  return true;
}

namespace {

std::string hex32(std::uint32_t v) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%08X", v);
  return text;
}

}  // namespace

void check_block_header(const std::uint8_t* p, std::size_t size, const BlockInfo& e, const std::string& part) {
  check_block_header(p, size, e, part, crc32c(p + layout::kBlockHeaderSize, size - layout::kBlockHeaderSize));
}

void check_block_header(const std::uint8_t* p, std::uint64_t size, const BlockInfo& e, const std::string& part,
                        std::uint32_t payload_crc) {
  // The block table requires stored_size > 32 for framed files; checked again
  // here so that this function stands on its own.
  if (size <= layout::kBlockHeaderSize)
    throw Error(ErrorClass::Malformed, part + "stored_size " + std::to_string(size) + " leaves no room for a payload");
  if (std::memcmp(p, layout::kBlockSignature.data(), 4) != 0)
    throw Error(ErrorClass::Malformed, part + "the block header does not start with IVBK");
  const std::uint32_t header_crc = crc32c(p, layout::kBlockHeaderCrc);
  const std::uint32_t stored_header_crc = layout::load<std::uint32_t>(p + layout::kBlockHeaderCrc);
  if (header_crc != stored_header_crc)
    throw Error(ErrorClass::Checksum, part + "block header CRC-32C is " + hex32(header_crc) + " but header_crc says " +
                                          hex32(stored_header_crc));
  auto mismatch = [&](const char* field, std::uint64_t header, std::uint64_t index) {
    if (header != index)
      throw Error(ErrorClass::Malformed, part + "the block header's " + field + " is " + std::to_string(header) +
                                             " but the index entry says " + std::to_string(index));
  };
  mismatch("stream", p[layout::kBlockStream], e.stream);
  mismatch("codec", p[layout::kBlockCodec], e.codec);
  mismatch("flags", p[layout::kBlockFlags], e.flags);
  mismatch("level", p[layout::kBlockLevel], e.level);
  mismatch("first_element", layout::load<std::uint64_t>(p + layout::kBlockFirstElement), e.first_element);
  mismatch("element_count", layout::load<std::uint32_t>(p + layout::kBlockElementCount), e.element_count);
  mismatch("payload_size", layout::load<std::uint32_t>(p + layout::kBlockPayloadSize), size - layout::kBlockHeaderSize);
  const std::uint32_t stored_payload_crc = layout::load<std::uint32_t>(p + layout::kBlockPayloadCrc);
  if (payload_crc != stored_payload_crc)
    throw Error(ErrorClass::Checksum, part + "payload CRC-32C is " + hex32(payload_crc) + " but payload_crc says " +
                                          hex32(stored_payload_crc));
}

}  // namespace ivol::detail
