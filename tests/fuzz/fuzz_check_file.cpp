// libFuzzer harness: check_file and the Reader's views on arbitrary bytes.
// Whatever the input, they must return or throw ivol::Error: no crash, no
// out-of-bounds access, no undefined behaviour, no unbounded allocation.
//
//   clang++ -fsanitize=fuzzer,address,undefined ... (see tests/fuzz/run.sh)
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include <cstring>

#include "ivol/check.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"

extern "C" std::size_t LLVMFuzzerMutate(std::uint8_t* data, std::size_t size, std::size_t max_size);

namespace {

template <typename T>
T get(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename T>
void put(std::uint8_t* p, T v) {
  std::memcpy(p, &v, sizeof v);
}

// Recomputes every CRC a mutation broke (blocks, index, footer, header),
// following the file's own offsets where they make sense, so that the
// fuzzer reaches the structural checks behind the checksums. Half of the
// time only, so that checksum handling stays fuzzed too.
void reseal(std::uint8_t* f, std::size_t size) {
  if (size < 72) return;
  const std::uint32_t header_size = get<std::uint32_t>(f + 12);
  if (header_size >= 8 && header_size <= size - 32) put(f + header_size - 4, ivol::crc32c(f, header_size - 4));
  std::uint8_t* footer = f + size - 32;
  const std::uint64_t index_offset = get<std::uint64_t>(footer);
  const std::uint64_t index_size = get<std::uint64_t>(footer + 8);
  if (index_offset < size && index_size <= size - index_offset && index_size >= 48) {
    std::uint8_t* index = f + index_offset;
    const std::uint32_t fixed = get<std::uint32_t>(index + 4);
    const unsigned depth = index[10];
    const std::uint32_t count = get<std::uint32_t>(index + 40);
    const std::uint32_t entry = get<std::uint32_t>(index + 44);
    const std::uint64_t table = std::uint64_t{fixed} + 8ull * (depth + 1);
    if (entry >= 32 && entry <= 4096 && table <= index_size && count <= (index_size - table) / entry)
      for (std::uint32_t b = 0; b < count; ++b) {
        std::uint8_t* e = index + table + std::uint64_t{b} * entry;
        const std::uint64_t at = get<std::uint64_t>(e);
        const std::uint32_t stored = get<std::uint32_t>(e + 20);
        if (at < size && stored <= size - at) put(e + 24, ivol::crc32c(f + at, stored));
      }
    put(footer + 16, ivol::crc32c(index, index_size));
  }
  put(footer + 20, ivol::crc32c(footer, 20));
}

}  // namespace

extern "C" std::size_t LLVMFuzzerCustomMutator(std::uint8_t* data, std::size_t size, std::size_t max_size,
                                               unsigned int seed) {
  size = LLVMFuzzerMutate(data, size, max_size);
  if (seed & 1u) reseal(data, size);
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
    if (ivol::voxel_count(d) <= (1u << 16)) {
      reader.read_lod(0);
      if (reader.layout().depth > 0) reader.read_lod(1);
    }
    reader.voxel_value(d[0] - 1, d[1] - 1, d[2] - 1);
    reader.read_slice(ivol::Axis::Z, d[2] / 2 < d[2] ? d[2] / 2 : 0);
  } catch (const ivol::Error&) {
  }
  return 0;
}
