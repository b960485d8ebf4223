// Salvage (spec §18): a format 1.3 file whose footer or index is missing or
// damaged, read from its framed blocks alone. Internal to libformat.
#pragma once

#include <string>

#include "ivol/reader.hpp"
#include "random_access_file.hpp"

namespace ivol::detail {

struct SalvagedFile {
  FileInfo info;  // the rebuilt index: only blocks that can be placed; info.salvage set
  // The metadata text to use (stream 1, else stream 6), empty when neither survived.
  std::string metadata_text;
};

// Scans the blocks after the header and rebuilds the index; `reason` says why
// the index could not be used. Throws Error when not even the header (its
// first 80 bytes) is sound, or the file is not framed: nothing can be salvaged.
SalvagedFile salvage_file(RandomAccessFile& file, const std::string& reason);

// read_file_structure(), or with `salvage` when it fails, salvage_file();
// `metadata_text` then holds the salvaged metadata (empty: none survived).
FileInfo read_or_salvage(RandomAccessFile& file, bool salvage, std::string& metadata_text);

}  // namespace ivol::detail
