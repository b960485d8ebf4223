// Raw volumes through standard input and output ("-"), streamed: no
// temporary file, nothing held but the slab in hand.
#pragma once

#include <memory>
#include <string>

#include "raw_io.hpp"
#include "slab_io.hpp"

namespace ivol::cli {

// Reads a raw volume of `layout` from standard input, front to back; slabs
// may overlap the previous one (a keep rule's margin) but never go back
// further. Exactly the layout's bytes must come, then the end of input.
std::unique_ptr<convert::SlabReader> stdin_raw_slabs(const convert::RawLayout& layout);
// What standard input gave the reader: its size and SHA-256, hashed while
// read (provenance.sources); empty until the reader reached the volume's end.
struct StdinDigest {
  std::uint64_t bytes = 0;
  std::string sha256;
};
StdinDigest stdin_digest();

// Writes the slabs' samples to standard output in the given byte order.
std::unique_ptr<convert::SlabWriter> stdout_raw_slabs(const convert::DenseVolume& shape, bool big_endian);

}  // namespace ivol::cli
