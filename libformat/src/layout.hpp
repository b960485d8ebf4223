// Byte layout of the on-disk structures (spec §4–§6): sizes, offsets and
// little-endian field access. Internal to libformat.
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "libformat assumes a little-endian host; the file format is little-endian");

namespace ivol::layout {

constexpr std::array<unsigned char, 8> kSignature = {0x89, 'I', 'V', 'O', 'L', 0x0D, 0x0A, 0x0A};
constexpr std::array<unsigned char, 8> kEndSignature = {'I', 'V', 'O', 'L', '_', 'E', 'N', 'D'};
constexpr std::array<unsigned char, 4> kIndexSignature = {'I', 'V', 'I', 'X'};

constexpr std::uint16_t kVersionMajor = 1;
constexpr std::uint16_t kVersionMinor = 1;            // written only for the kinds of spec §8A
constexpr std::uint16_t kVersionMinorBytePlanes = 2;  // files with a block of codec 2
constexpr std::uint16_t kVersionMinorFramed = 3;      // files with framed blocks (required feature bit 0)

// Header (§4)
constexpr std::uint32_t kHeaderSize = 40;
constexpr std::uint32_t kMaxHeaderSize = 4096;
constexpr std::size_t kHeaderVersionMajor = 8;
constexpr std::size_t kHeaderVersionMinor = 10;
constexpr std::size_t kHeaderSizeField = 12;
constexpr std::size_t kHeaderRequiredFeatures = 16;
constexpr std::size_t kHeaderOptionalFeatures = 24;
constexpr std::size_t kHeaderReserved = 32;

// Framed blocks (§4, §7; since 1.3, required feature bit 0): an 80-byte header
// with the volume descriptor, and a 32-byte block header before every payload.
constexpr std::uint64_t kFeatureFramedBlocks = 1;
constexpr std::uint32_t kFramedHeaderSize = 80;
constexpr std::size_t kHeaderDescriptor = 36;  // copy of index fixed part bytes 8 .. 40
constexpr std::size_t kDescriptorSize = 32;
constexpr std::size_t kHeaderDescriptorReserved = 68;  // 8 bytes, for the brick layout
constexpr std::array<unsigned char, 4> kBlockSignature = {'I', 'V', 'B', 'K'};
constexpr std::uint32_t kBlockHeaderSize = 32;
constexpr std::size_t kBlockStream = 4;
constexpr std::size_t kBlockCodec = 5;
constexpr std::size_t kBlockFlags = 6;
constexpr std::size_t kBlockLevel = 7;
constexpr std::size_t kBlockFirstElement = 8;
constexpr std::size_t kBlockElementCount = 16;
constexpr std::size_t kBlockPayloadSize = 20;
constexpr std::size_t kBlockPayloadCrc = 24;
constexpr std::size_t kBlockHeaderCrc = 28;
constexpr std::uint8_t kStreamEarlyMetadata = 6;  // ignorable; the metadata as known before the values

// Footer (§5)
constexpr std::size_t kFooterSize = 32;
constexpr std::size_t kFooterIndexOffset = 0;
constexpr std::size_t kFooterIndexSize = 8;
constexpr std::size_t kFooterIndexCrc = 16;
constexpr std::size_t kFooterCrc = 20;
constexpr std::size_t kFooterEndSignature = 24;

// Index fixed part (§6.1)
constexpr std::uint32_t kIndexFixedSize = 48;
constexpr std::uint32_t kMaxIndexFixedSize = 4096;
constexpr std::size_t kIndexFixedSizeField = 4;
constexpr std::size_t kIndexStructureKind = 8;
constexpr std::size_t kIndexValueEncoding = 9;
constexpr std::size_t kIndexDepth = 10;
constexpr std::size_t kIndexCellLog2 = 11;  // nested grid; reserved otherwise
constexpr std::size_t kIndexSizeX = 12;
constexpr std::size_t kIndexScale = 24;
constexpr std::size_t kIndexOffset = 32;
constexpr std::size_t kIndexBlockCount = 40;
constexpr std::size_t kIndexBlockEntrySize = 44;

// Block table entry (§6.3)
constexpr std::uint32_t kBlockEntrySize = 32;
constexpr std::uint32_t kMaxBlockEntrySize = 4096;
constexpr std::size_t kEntryFileOffset = 0;
constexpr std::size_t kEntryFirstElement = 8;
constexpr std::size_t kEntryElementCount = 16;
constexpr std::size_t kEntryStoredSize = 20;
constexpr std::size_t kEntryCrc = 24;
constexpr std::size_t kEntryStream = 28;
constexpr std::size_t kEntryCodec = 29;
constexpr std::size_t kEntryFlags = 30;
constexpr std::size_t kEntryLevel = 31;

constexpr std::uint8_t kStructureOctree = 1;
constexpr std::uint8_t kFlagIgnorable = 0x01;
constexpr unsigned kMaxDepth = 31;
// Bricked grid (spec §8A.4): bricks up to 256^3, so that a brick of float32
// values (64 MiB) still fits in one block.
constexpr unsigned kMaxBrickLog2 = 8;
constexpr std::uint64_t kMaxBlockDecodedBytes = 64ull << 20;
constexpr std::uint64_t kMaxMetadataBytes = 16ull << 20;
constexpr std::uint64_t kOffsetMask = (1ull << 56) - 1;

template <typename T>
T load(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

template <typename T>
void store(unsigned char* p, T v) {
  std::memcpy(p, &v, sizeof(T));
}

}  // namespace ivol::layout
