// CRC-32C (Castagnoli), the checksum of every part of an .ivol file (spec §2.1).
#pragma once

#include <cstddef>
#include <cstdint>

namespace ivol {

// Continues a CRC-32C over `size` more bytes; start with crc = 0.
std::uint32_t crc32c_extend(std::uint32_t crc, const void* data, std::size_t size);

inline std::uint32_t crc32c(const void* data, std::size_t size) { return crc32c_extend(0, data, size); }

}  // namespace ivol
