// libFuzzer harness: check_file and the Reader's views on arbitrary bytes.
// Whatever the input, they must return or throw ivol::Error: no crash, no
// out-of-bounds access, no undefined behaviour, no unbounded allocation.
//
//   clang++ -fsanitize=fuzzer,address,undefined ... (see tests/fuzz/run.sh)
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol_mutator.hpp"

extern "C" std::size_t LLVMFuzzerMutate(std::uint8_t* data, std::size_t size, std::size_t max_size);

// A quarter of the mutations work on a block's decoded content (metadata
// text and node words more often than values; valid frames, valid CRCs), an
// eighth change a field of the index to a value near a limit (resealed); of
// the rest, half have their CRCs resealed (tests/fuzz/ivol_mutator.hpp).
extern "C" std::size_t LLVMFuzzerCustomMutator(std::uint8_t* data, std::size_t size, std::size_t max_size,
                                               unsigned int seed) {
  if ((seed & 3u) == 3u)
    if (const std::size_t mutated = ivol::fuzz::mutate_decoded_block(data, size, max_size, seed)) return mutated;
  if ((seed & 7u) == 2u)
    if (const std::size_t mutated = ivol::fuzz::mutate_index_field(data, size, seed)) return mutated;
  size = LLVMFuzzerMutate(data, size, max_size);
  if (seed & 1u) ivol::fuzz::reseal(data, size);
  return size;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/dev/shm/ivol-fuzz-" + std::to_string(getpid()) + ".ivol";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  if (size > 0) std::fwrite(data, 1, size, f);  // an empty input may come with a null pointer
  std::fclose(f);
  (void)ivol::check_file(path);
  try {
    ivol::Reader reader(path);
    const ivol::Dims d = reader.layout().dims;
    // Per axis first: the product of three sizes up to 2^31 wraps 64 bits.
    if (d[0] <= (1u << 16) && d[1] <= (1u << 16) && d[2] <= (1u << 16) && ivol::voxel_count(d) <= (1u << 16)) {
      reader.read_lod(0);
      if (reader.layout().depth > 0) reader.read_lod(1);
    }
    reader.voxel_value(d[0] - 1, d[1] - 1, d[2] - 1);
    // A slice's output is the caller's to bound (a valid file may be 2^31 voxels a side).
    if (std::uint64_t{d[0]} * d[1] <= (1u << 22)) reader.read_slice(ivol::Axis::Z, d[2] / 2 < d[2] ? d[2] / 2 : 0);
  } catch (const ivol::Error&) {
  }
  return 0;
}
