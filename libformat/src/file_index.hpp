// Reading and checking the container: header, footer, index, level table and
// block table, in the order of spec §13. Internal to libformat.
#pragma once

#include "ivol/reader.hpp"
#include "random_access_file.hpp"

namespace ivol::detail {

// Element width of a known stream (1, 8, or the value encoding's width).
std::size_t stream_width(std::uint8_t stream, ValueEncoding encoding);
bool is_known_stream(std::uint8_t stream);
// Streams 4 and 5 belong to the rectilinear and nested grids only; in files
// of other kinds they are unknown streams (spec §6.4).
bool is_known_stream(std::uint8_t stream, StructureKind kind);

FileInfo read_file_structure(RandomAccessFile& file);

}  // namespace ivol::detail
