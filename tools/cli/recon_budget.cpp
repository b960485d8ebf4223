// The run's memory default (recon_budget.hpp).
#include "recon_budget.hpp"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace ivol::cli {
namespace {

constexpr std::uint64_t kMiB = std::uint64_t{1} << 20;
constexpr std::uint64_t kLeast = 256 * kMiB;
constexpr std::uint64_t kMost = std::uint64_t{1} << 40;
// Limits at or above this mean none (cgroup v1 writes 2^63 rounded to pages).
constexpr std::uint64_t kNoLimit = std::uint64_t{1} << 62;

std::string under_test_root(const std::string& path) {
  const char* root = std::getenv("IVOL_TEST_ROOT");
  return root != nullptr && *root != '\0' ? std::string(root) + path : path;
}

// The file's first word as bytes; 0 when absent, "max" or not a number.
std::uint64_t read_limit(const std::string& path) {
  std::ifstream in(under_test_root(path));
  std::string word;
  if (!(in >> word) || word == "max") return 0;
  char* end = nullptr;
  const unsigned long long value = std::strtoull(word.c_str(), &end, 10);
  return end != word.c_str() && *end == '\0' && value < kNoLimit ? value : 0;
}

// The tightest limit of `file` in the cgroup `path` under `mount` and in the
// cgroups above it (a child's own limit may be looser than its parent's).
std::uint64_t tightest_limit(const std::string& mount, std::string path, const std::string& file) {
  std::uint64_t limit = 0;
  while (true) {
    const std::uint64_t here = read_limit(mount + (path == "/" ? "" : path) + "/" + file);
    if (here > 0) limit = limit == 0 ? here : std::min(limit, here);
    if (path.empty() || path == "/") break;
    const auto slash = path.find_last_of('/');
    path = slash == 0 || slash == std::string::npos ? "/" : path.substr(0, slash);
  }
  return limit;
}

// The memory cgroup's limit of this process (0: none found).
std::uint64_t cgroup_limit() {
  std::ifstream in(under_test_root("/proc/self/cgroup"));
  std::string line;
  std::uint64_t limit = 0;
  auto tighten = [&](std::uint64_t l) {
    if (l > 0) limit = limit == 0 ? l : std::min(limit, l);
  };
  while (std::getline(in, line)) {
    // "4:memory:/a/b" (v1) or "0::/a/b" (v2)
    const auto first = line.find(':');
    const auto second = first == std::string::npos ? std::string::npos : line.find(':', first + 1);
    if (second == std::string::npos) continue;
    const std::string controllers = line.substr(first + 1, second - first - 1);
    const std::string path = line.substr(second + 1);
    std::istringstream list(controllers);
    std::string controller;
    bool memory = false;
    while (std::getline(list, controller, ','))
      if (controller == "memory") memory = true;
    if (memory) tighten(tightest_limit("/sys/fs/cgroup/memory", path, "memory.limit_in_bytes"));
    if (controllers.empty()) tighten(tightest_limit("/sys/fs/cgroup", path, "memory.max"));
  }
  return limit;
}

std::uint64_t mem_available() {
  std::ifstream in(under_test_root("/proc/meminfo"));
  std::string key, unit;
  std::uint64_t value = 0;
  while (in >> key >> value) {
    std::getline(in, unit);
    if (key == "MemAvailable:") return value * 1024;
  }
  return 0;
}

std::string mib(std::uint64_t bytes) { return std::to_string(bytes / kMiB) + " MiB"; }

}  // namespace

MemoryBudget memory_budget(std::uint64_t given_mib) {
  if (given_mib > 0) return {given_mib * kMiB, "--memory " + std::to_string(given_mib)};
  std::uint64_t basis = cgroup_limit();
  std::string rule = "half of the memory cgroup's limit (" + mib(basis) + ")";
  if (basis == 0) {
    basis = mem_available();
    rule = "half of MemAvailable (" + mib(basis) + ")";
  }
  std::uint64_t bytes = basis / 2;
  if (bytes < kLeast) bytes = kLeast, rule += ", raised to the least, " + mib(kLeast);
  if (bytes > kMost) bytes = kMost, rule += ", lowered to the most, " + mib(kMost);
  return {bytes, rule};
}

ReconDiskNeeds recon_disk_needs(const recon::ScanGeometry& geometry, const recon::VolumeGrid& grid,
                                const recon::FdkOptions& fdk,
                                const std::optional<recon::DetectionMaskOptions>& detection, ValueEncoding encoding,
                                bool octree_spill, const std::string& output,
                                const std::string& writer_temp_directory) {
  ReconDiskNeeds needs;
  needs.reconstruction = convert::ivol_disk_needs(Dims{grid.size[0], grid.size[1], grid.size[2]}, encoding,
                                                  octree_spill, output, writer_temp_directory);
  const std::string temp = fdk.temp_directory;
  if (const std::uint64_t rows = recon::filtered_rows_disk_bound(geometry, fdk); rows > 0)
    needs.reconstruction.push_back({temp, rows, "the filtered detector rows beyond their share of --memory", true});
  if (detection) {
    if (const std::uint64_t preview = recon::detection_temp_bytes(geometry, fdk, grid, *detection); preview > 0)
      needs.preview.push_back(
          {temp, preview, "the detection preview's cells, samples and filtered rows beyond their share of --memory",
           true});
  }
  return needs;
}

}  // namespace ivol::cli
