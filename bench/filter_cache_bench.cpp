// Filtering time against the number of slabs (issue 23 item 3): the same
// dense reconstruction cut into slabs of S slices, with each slab filtering
// its own detector rows (the path before the cache, cache_filtered_rows =
// false) and with each row filtered once (the default), side by side in one
// run. Prints per S: slabs, rows filtered (× views), filtering seconds (the
// filter kernel's events), reading seconds, total seconds, the filtered
// rows' peak host bytes and whether the two volumes are bit-equal.
//
//   filter_cache_bench [--size N] [--views V] [--detector D] [--slices S,S,...]
//                      [--memory BYTES]
//
// --memory bounds the filtered rows' host memory (0: the default, a quarter
// of the RAM); beyond it they go to a file in $TMPDIR.
// Default: 256³ voxels of 1 mm, 360 views of 384² pixels of 1.6 mm,
// SID/SDD 600/1200 mm (fdk_bench's scan), slices 256,64,16,4.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"

using namespace ivol::recon;

int main(int argc, char** argv) {
  std::uint32_t size = 256;
  std::size_t views = 360;
  int detector = 384;
  std::vector<std::uint32_t> slices_list = {256, 64, 16, 4};
  std::uint64_t memory = 0;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (a + 1 >= argc) {
      std::fprintf(stderr, "filter_cache_bench: %s needs a value\n", arg.c_str());
      return 1;
    }
    const std::string value = argv[++a];
    if (arg == "--size") {
      size = static_cast<std::uint32_t>(std::stoul(value));
    } else if (arg == "--views") {
      views = std::stoul(value);
    } else if (arg == "--detector") {
      detector = std::stoi(value);
    } else if (arg == "--memory") {
      memory = std::stoull(value);
    } else if (arg == "--slices") {
      slices_list.clear();
      std::stringstream list(value);
      for (std::string item; std::getline(list, item, ',');) slices_list.push_back(std::stoul(item));
    } else {
      std::fprintf(stderr, "filter_cache_bench: unknown option %s\n", arg.c_str());
      return 1;
    }
  }
  const double pitch = 1.6;
  const ScanGeometry geometry =
      circular_scan({detector, detector, pitch, pitch}, views, 600.0, 1200.0, 2 * M_PI, 0.0, 0.0, 0.0);
  const VolumeGrid grid = VolumeGrid::centred({size, size, size}, 1.0);
  std::printf("filter_cache_bench: %u^3 voxels, %zu views of %d^2 pixels\n", size, views, detector);
  const auto projecting = std::chrono::steady_clock::now();
  InMemoryProjections projections = project_scan(shepp_logan_3d(0.45 * size), geometry);
  std::printf("projected in %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - projecting).count());
  std::printf("%7s %6s %-9s %14s %10s %9s %9s %14s %s\n", "slices", "slabs", "filter", "rows_filtered",
              "filter_s", "read_s", "total_s", "rows_host_MiB", "bit-equal");
  for (std::uint32_t slices : slices_list) {
    std::vector<float> volumes[2];
    for (int cached = 0; cached < 2; ++cached) {
      FdkOptions options;
      options.max_slab_slices = slices;
      options.cache_filtered_rows = cached == 1;
      options.filtered_rows_memory_limit = memory;
      FdkReport report;
      volumes[cached] = reconstruct_fdk_dense(projections, geometry, grid, options, &report);
      std::printf("%7u %6zu %-9s %14llu %10.2f %9.2f %9.2f %14.1f %s\n", slices, report.slab_count,
                  cached ? "once" : "per-slab", static_cast<unsigned long long>(report.rows_filtered),
                  report.timings.filtering, report.timings.reading, report.timings.total,
                  static_cast<double>(report.filtered_rows_host_bytes) / (1 << 20),
                  cached ? (std::memcmp(volumes[0].data(), volumes[1].data(), volumes[0].size() * sizeof(float)) == 0
                                ? "yes"
                                : "NO")
                         : "");
      std::fflush(stdout);
    }
  }
  return 0;
}
