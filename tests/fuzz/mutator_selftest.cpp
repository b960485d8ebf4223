// The check_file fuzzer's mutator (ivol_mutator.hpp) must keep valid files
// valid where it only re-encodes, and keep every checksum right where it
// changes something; else the fuzzer stops at the first CRC, as it did on
// format 1.3 files (framed blocks) before. For each valid conformance
// vector given:
// - reseal leaves the file byte for byte as its writer made it;
// - every block decoded and encoded again (the elements unchanged) gives a
//   file that check_file accepts, and every file has such blocks;
// - every index field mutation gives a file whose problems, if any, are
//   not checksum problems.
//   mutator_selftest VECTOR.ivol...
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "ivol/check.hpp"
#include "ivol_mutator.hpp"

// The elements unchanged: only the re-encoding is tested.
extern "C" std::size_t LLVMFuzzerMutate(std::uint8_t*, std::size_t size, std::size_t) { return size; }

namespace {

std::vector<std::uint8_t> load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

ivol::CheckReport check_bytes(const std::vector<std::uint8_t>& bytes, std::size_t size, const std::string& path) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(bytes.data()), size);
  return ivol::check_file(path);
}

std::string first_problem(const ivol::CheckReport& r) {
  return r.problems.empty() ? std::string() : r.problems.front().message;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string scratch =
      (std::filesystem::temp_directory_path() / ("ivol-mutator-selftest-" + std::to_string(::getpid()) + ".ivol"))
          .string();
  int failures = 0, files = 0, re_encoded = 0, index_mutations = 0;
  for (int a = 1; a < argc; ++a) {
    const std::string path = argv[a];
    const std::vector<std::uint8_t> original = load(path);
    if (!ivol::check_file(path).ok()) continue;  // only valid files
    ++files;
    std::vector<std::uint8_t> f = original;
    ivol::fuzz::reseal(f.data(), f.size());
    if (f != original) {
      std::printf("FAIL %s: reseal changed a valid file\n", path.c_str());
      ++failures;
    }
    std::uint64_t index_offset = 0;
    std::uint32_t blocks = 0;
    std::memcpy(&index_offset, original.data() + original.size() - 32, 8);
    std::memcpy(&blocks, original.data() + index_offset + 40, 4);
    int file_re_encoded = 0;
    for (unsigned b = 0; b < blocks; ++b) {
      f = original;
      f.resize(original.size() + 4096);
      const std::size_t n = ivol::fuzz::mutate_decoded_block(f.data(), original.size(), f.size(), b << 3);
      if (n == 0) continue;  // a block of more than 1 MiB decoded, or fewer blocks than b
      ++re_encoded;
      ++file_re_encoded;
      const ivol::CheckReport r = check_bytes(f, n, scratch);
      if (!r.ok()) {
        std::printf("FAIL %s: block %u re-encoded: %s\n", path.c_str(), b, first_problem(r).c_str());
        ++failures;
      }
    }
    // Every vector has blocks of less than 1 MiB (the metadata at least).
    if (file_re_encoded == 0) {
      std::printf("FAIL %s: no block could be decoded and encoded again\n", path.c_str());
      ++failures;
    }
    for (unsigned seed = 0; seed < 4096; seed += 73) {
      f = original;
      const std::size_t n = ivol::fuzz::mutate_index_field(f.data(), f.size(), seed * 2654435761u);
      if (n == 0) continue;
      ++index_mutations;
      for (const auto& p : check_bytes(f, n, scratch).problems)
        if (p.error_class == ivol::ErrorClass::Checksum) {
          std::printf("FAIL %s: index mutation %u left a checksum problem: %s\n", path.c_str(), seed,
                      p.message.c_str());
          ++failures;
          break;
        }
    }
  }
  std::filesystem::remove(scratch);
  std::printf("%d valid files, %d blocks re-encoded, %d index mutations, %d failures\n", files, re_encoded,
              index_mutations, failures);
  return failures == 0 && re_encoded > 0 && index_mutations > 0 ? 0 : 1;
}
