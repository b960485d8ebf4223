// Format 1.3 framing (spec §4, §7.1): the volume descriptor in the file
// header and the 32-byte header in front of every block. Shared by the
// writer, the reader's checks and the salvage scan. Internal to libformat.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "ivol/geometry.hpp"
#include "ivol/reader.hpp"

namespace ivol::detail {

// Index fixed part bytes 8 .. 40, which the framed header repeats at 36 .. 68.
std::array<unsigned char, 32> volume_descriptor(const VolumeLayout& layout);

// The 32-byte block header of a payload of `payload_size` bytes whose CRC-32C
// is `payload_crc`; `entry` gives stream, codec, flags, level and elements.
std::array<unsigned char, 32> block_header(const BlockInfo& entry, std::uint32_t payload_size,
                                           std::uint32_t payload_crc);

// What a block header says, read without the index (salvage).
struct BlockHeader {
  BlockInfo entry;  // stream .. element_count; file_offset and sizes unset
  std::uint32_t payload_size = 0;
  std::uint32_t payload_crc = 0;
};
// True when `p` (32 bytes) starts with IVBK and its header_crc holds.
bool parse_block_header(const unsigned char* p, BlockHeader& out);

// Checks the header at the start of a framed block's stored bytes against its
// index entry (spec §7.1): `part` names the block in messages. The stored
// bytes' CRC has been checked already.
void check_block_header(const std::uint8_t* stored, std::size_t size, const BlockInfo& entry, const std::string& part);
// The same, from the 32 header bytes alone, for a block of `size` stored bytes
// whose payload's CRC-32C the caller computed (a block too large to hold).
void check_block_header(const std::uint8_t* header, std::uint64_t size, const BlockInfo& entry, const std::string& part,
                        std::uint32_t payload_crc);

}  // namespace ivol::detail
