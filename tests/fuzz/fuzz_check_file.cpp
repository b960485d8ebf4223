// libFuzzer harness: check_file and the Reader's views on arbitrary bytes.
// Whatever the input, they must return or throw ivol::Error: no crash, no
// out-of-bounds access, no undefined behaviour, no unbounded allocation.
//
//   clang++ -fsanitize=fuzzer,address,undefined ... (see tests/fuzz/run.sh)
#include <unistd.h>
#include <zstd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

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

// Mutates the decoded content of one block (metadata text, node words,
// values, borders, cell words) instead of its stored bytes: decodes it,
// lets libFuzzer mutate the elements, encodes them again with the block's
// codec, moves the blocks after it and the index, and reseals every CRC.
// Mutating a zstd frame's bytes only ever reaches zstd's error paths; this
// reaches the checks behind a valid frame (nesting, node numbering, sizes).
// Returns 0 when the file's layout does not allow it.
std::size_t mutate_decoded_block(std::uint8_t* f, std::size_t size, std::size_t max_size, unsigned seed) {
  if (size < 72 + 48) return 0;
  const std::uint32_t header_size = get<std::uint32_t>(f + 12);
  const std::uint64_t index_offset = get<std::uint64_t>(f + size - 32);
  const std::uint64_t index_size = get<std::uint64_t>(f + size - 24);
  if (header_size < 40 || index_offset < header_size || index_offset > size - 32 ||
      index_size != size - 32 - index_offset || index_size < 48)
    return 0;
  const std::uint8_t* index = f + index_offset;
  const std::uint32_t fixed = get<std::uint32_t>(index + 4);
  const std::uint64_t table = std::uint64_t{fixed} + 8ull * (index[10] + 1);
  const std::uint32_t count = get<std::uint32_t>(index + 40);
  const std::uint32_t entry = get<std::uint32_t>(index + 44);
  if (count == 0 || entry < 32 || entry > 4096 || table > index_size || count > (index_size - table) / entry) return 0;
  const std::uint32_t b = (seed >> 2) % count;
  const std::uint8_t* e = index + table + std::uint64_t{b} * entry;
  const std::uint64_t at = get<std::uint64_t>(e);
  const std::uint32_t stored = get<std::uint32_t>(e + 20);
  const std::uint32_t elements = get<std::uint32_t>(e + 16);
  const std::uint8_t stream = e[28], codec = e[29];
  if (at < header_size || at > index_offset || stored > index_offset - at || codec > 2) return 0;
  const std::size_t width = stream == 1                  ? 1
                            : stream == 3                ? (index[9] == 3 ? 4 : 2)
                            : stream == 2 || stream == 5 ? 8
                                                         : 4;
  const std::uint64_t decoded_size = std::uint64_t{elements} * width;
  if (decoded_size == 0 || decoded_size > (1u << 20)) return 0;
  std::vector<std::uint8_t> content(decoded_size + 256);
  if (codec == 0) {
    if (stored != decoded_size) return 0;
    std::memcpy(content.data(), f + at, stored);
  } else {
    const std::size_t got = ZSTD_decompress(content.data(), decoded_size, f + at, stored);
    if (ZSTD_isError(got) || got != decoded_size) return 0;
  }
  // Elements stay whole: the mutated size is a multiple of the width (the
  // metadata, of width 1, may grow or shrink).
  std::size_t n = LLVMFuzzerMutate(content.data(), decoded_size, content.size());
  n -= n % width;
  if (n == 0) return 0;
  std::vector<std::uint8_t> encoded;
  if (codec == 0) {
    encoded.assign(content.begin(), content.begin() + n);
  } else {
    encoded.resize(ZSTD_compressBound(n));
    const std::size_t z = ZSTD_compress(encoded.data(), encoded.size(), content.data(), n, 1);
    if (ZSTD_isError(z)) return 0;
    encoded.resize(z);
  }
  const std::int64_t delta = static_cast<std::int64_t>(encoded.size()) - stored;
  if (static_cast<std::int64_t>(size) + delta > static_cast<std::int64_t>(max_size)) return 0;
  std::vector<std::uint8_t> out(f, f + at);
  out.insert(out.end(), encoded.begin(), encoded.end());
  out.insert(out.end(), f + at + stored, f + size);
  std::uint8_t* new_index = out.data() + index_offset + delta;
  for (std::uint32_t k = 0; k < count; ++k) {
    std::uint8_t* ek = new_index + table + std::uint64_t{k} * entry;
    if (k == b) {
      put<std::uint32_t>(ek + 16, static_cast<std::uint32_t>(n / width));
      put<std::uint32_t>(ek + 20, static_cast<std::uint32_t>(encoded.size()));
    } else if (get<std::uint64_t>(ek) > at) {
      put<std::uint64_t>(ek, get<std::uint64_t>(ek) + delta);
    }
  }
  put<std::uint64_t>(out.data() + out.size() - 32, index_offset + delta);
  std::memcpy(f, out.data(), out.size());
  reseal(f, out.size());
  return out.size();
}

}  // namespace

// A quarter of the mutations work on a block's decoded content (valid
// frames, valid CRCs); of the rest, half have their CRCs resealed.
extern "C" std::size_t LLVMFuzzerCustomMutator(std::uint8_t* data, std::size_t size, std::size_t max_size,
                                               unsigned int seed) {
  if ((seed & 3u) == 3u)
    if (const std::size_t mutated = mutate_decoded_block(data, size, max_size, seed)) return mutated;
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
