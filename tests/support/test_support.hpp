// Helpers shared by the tests: random volumes, temporary files, an
// independent dense reference for levels of detail, and byte patching.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "ivol/encoding.hpp"
#include "ivol/geometry.hpp"

namespace ivol::test {

// A fresh, empty directory for this test, removed at exit.
std::string temp_dir();
std::string temp_path(const std::string& name);

std::vector<std::uint8_t> read_bytes(const std::string& path);
void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes);

// Random volume: blobs of constant value in a background (so that leaves
// merge), optional noise.
std::vector<float> random_volume(const Dims& dims, std::mt19937_64& rng, double noise, int blobs = 4);

// Stored bits of every voxel as the encoding holds the source value, computed
// here independently of libformat's builder.
std::uint32_t reference_encode(ValueEncoding encoding, double value);
double reference_decode(ValueEncoding encoding, std::uint32_t bits);

// Level of detail `lod` of a dense volume of stored bits, by box filtering in
// long double over the non-padding voxels (spec §12.3), then encoding.
std::vector<std::uint32_t> reference_lod(const std::vector<std::uint32_t>& bits, const Dims& dims,
                                         ValueEncoding encoding, unsigned lod);

// Distance in units of the last place between two stored values of the same
// encoding (0 = identical).
std::uint64_t ulp_distance(ValueEncoding encoding, std::uint32_t a, std::uint32_t b);

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};
// Runs a shell command and collects what it prints.
CommandResult run_command(const std::string& command);

// Rewrites the CRCs of header, index and footer after a test patched the file
// (so that the intended error, not a checksum error, is found first).
void refresh_container_checksums(std::vector<std::uint8_t>& file);

}  // namespace ivol::test
