// Structure-aware mutations of .ivol files for the check_file fuzzer: they
// keep every checksum valid, so that the fuzzer reaches the checks behind
// the checksums (the metadata's nesting, the index's rules, the node
// numbering) instead of stopping at the first CRC it broke.
#pragma once

#include <cstddef>
#include <cstdint>

namespace ivol::fuzz {

// Recomputes every CRC a mutation broke, following the file's own offsets
// where they make sense: each block's entry CRC and, in a file with framed
// blocks (format 1.3), its block header (fields copied from the index entry,
// payload_size, payload_crc, header_crc) and the header's volume descriptor
// (copied from the index's fixed part); then the index, footer and header
// CRCs. A mutation of the index thus reaches the reader as a valid index.
void reseal(std::uint8_t* file, std::size_t size);

// Mutates the decoded content of one block (metadata text, node words,
// values, borders, cell words) rather than its stored bytes: decodes it,
// lets libFuzzer (LLVMFuzzerMutate) mutate the elements, encodes them again
// with the block's codec, moves the blocks after it and the index, and
// reseals. `seed` picks the block; every other seed prefers the metadata
// and node blocks. Returns the new size, or 0 when the file's layout does
// not allow it (nothing is changed then).
std::size_t mutate_decoded_block(std::uint8_t* file, std::size_t size, std::size_t max_size, unsigned seed);

// Changes one field of the index (the fixed part, a level-table count or a
// block entry's element_count, first_element, level, stream or flags) to a
// value near a limit, then reseals. Returns the size, or 0 when there is no
// valid index to mutate.
std::size_t mutate_index_field(std::uint8_t* file, std::size_t size, unsigned seed);

}  // namespace ivol::fuzz
