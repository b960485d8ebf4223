// format_bench: what the .ivol format saves and what partial reads cost, for
// synthetic industrial-like volumes with noise (issue 2's benchmark).
//
// For each object and mode (lossless; full resolution kept only around the
// object) and block size: the file size against dense float32 and uint16,
// build/write/read throughput, and the time and bytes read for one slice, a
// 64^3 box and a 1/8-resolution preview, against reading everything. Every
// read opens a fresh Reader, so its bytes include the header, footer, index
// and metadata. The page cache is warm: times are CPU-bound, bytes read
// are what a cold read would fetch.
//
//   format_bench [--size N] [--quick]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "ivol/build.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "synthetic_volume.hpp"

namespace {

using namespace ivol;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct PartialRead {
  double seconds = 0;
  std::uint64_t bytes = 0;
};

template <class F>
PartialRead measure(const std::string& path, F&& read) {
  const auto t = Clock::now();
  Reader reader(path);
  read(reader);
  PartialRead r;
  r.seconds = since(t);
  r.bytes = reader.io_stats().bytes_read;  // header, footer, index and blocks
  return r;
}

std::string mib(std::uint64_t bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f", bytes / 1048576.0);
  return text;
}

std::string pct(std::uint64_t part, std::uint64_t whole) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f %%", 100.0 * part / whole);
  return text;
}

void run(synthetic::Object object, std::uint32_t n, bool keep_mode, std::uint32_t block_bytes,
         const std::vector<float>& volume, const std::vector<std::uint8_t>& keep, const std::string& dir) {
  const Dims dims{n, n, n};
  const std::uint64_t voxels = voxel_count(dims);
  BuildOptions options;
  if (keep_mode) options.keep_mask = keep.data();
  const BuildResult built = build_octree(volume.data(), dims, options);
  WriteOptions w;
  w.block_bytes = block_bytes;
  const std::string path = dir + "/bench.ivol";
  Metadata metadata;
  const WriteStats written = write_octree(built.octree, metadata, path, w);

  const PartialRead all = measure(path, [&](Reader& r) { r.read_lod(0); });
  const PartialRead slice_z = measure(path, [&](Reader& r) { r.read_slice(Axis::Z, n / 2); });
  const PartialRead slice_x = measure(path, [&](Reader& r) { r.read_slice(Axis::X, n / 2); });
  // A 64^3 box off-centre, on the pencil holder's wall (at 0.56 of the
  // half-width from the axis), and one in the middle of the volume.
  const std::uint32_t wall = static_cast<std::uint32_t>(n / 2 + 0.56 * n / 2) - 32;
  const PartialRead box_wall =
      measure(path, [&](Reader& r) { r.read_box(Box{{wall, n / 2 - 32, n / 2 - 32}, {wall + 64, n / 2 + 32, n / 2 + 32}}); });
  const PartialRead box_mid =
      measure(path, [&](Reader& r) { r.read_box(Box{{n / 2 - 32, n / 2 - 32, n / 2 - 32}, {n / 2 + 32, n / 2 + 32, n / 2 + 32}}); });
  const PartialRead preview = measure(path, [&](Reader& r) { r.read_lod(3); });

  const std::uint64_t file = written.file_bytes;
  std::printf("| %s | %s | %u KiB | %s | %.1fx | %.1fx | %.1f %% | %.2f | %.2f | %.0f | %.2f | %.0f | %lu |\n",
              synthetic::object_name(object), keep_mode ? "octree (margin 3)" : "lossless", block_bytes / 1024,
              mib(file).c_str(), 4.0 * voxels / file, 2.0 * voxels / file, 100.0 * built.kept_voxels / voxels,
              built.seconds, written.seconds, 4.0 * voxels / 1048576.0 / (built.seconds + written.seconds),
              all.seconds, 4.0 * voxels / 1048576.0 / all.seconds, static_cast<unsigned long>(written.block_count));
  std::printf("|   | partial reads |  | slice z: %s (%.0f ms) | slice x: %s (%.0f ms) | 64^3 off-centre: %s (%.0f ms) | 64^3 middle: %s (%.0f ms) | 1/8 preview: %s (%.0f ms) | all: %s | | | | |\n",
              pct(slice_z.bytes, file).c_str(), slice_z.seconds * 1e3, pct(slice_x.bytes, file).c_str(),
              slice_x.seconds * 1e3, pct(box_wall.bytes, file).c_str(), box_wall.seconds * 1e3,
              pct(box_mid.bytes, file).c_str(), box_mid.seconds * 1e3, pct(preview.bytes, file).c_str(),
              preview.seconds * 1e3, pct(all.bytes, file).c_str());
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  std::uint32_t n = 512;
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--size") && i + 1 < argc) n = static_cast<std::uint32_t>(std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--quick")) quick = true;
    else {
      std::fprintf(stderr, "usage: format_bench [--size N] [--quick]\n");
      return 1;
    }
  }
  const std::string dir = std::filesystem::temp_directory_path() / "ivol-format-bench";
  std::filesystem::create_directories(dir);
  std::printf("format_bench: %u^3 voxels, binary16 values, noise sigma 0.002/mm, zstd level 3\n\n", n);
  std::printf("| object | mode | block | file MiB | vs f32 | vs u16 | full-res voxels | build s | write s | "
              "build+write MiB/s (f32) | read all s | read MiB/s (f32) | blocks |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  const std::vector<std::uint32_t> block_sizes =
      quick ? std::vector<std::uint32_t>{WriteOptions{}.block_bytes}
            : std::vector<std::uint32_t>{4 << 10, 8 << 10, 16 << 10, 64 << 10, 256 << 10, 1 << 20};
  for (synthetic::Object object : {synthetic::Object::PencilHolder, synthetic::Object::Board, synthetic::Object::Pipe}) {
    synthetic::VolumeSpec spec;
    spec.dims = {n, n, n};
    spec.object = object;
    const std::vector<float> volume = synthetic::make_volume(spec);
    const std::vector<std::uint8_t> keep = threshold_keep_mask(volume.data(), spec.dims, spec.material / 2, 3);
    const std::uint32_t default_block = WriteOptions{}.block_bytes;
    if (object == synthetic::Object::PencilHolder) run(object, n, false, default_block, volume, keep, dir);
    for (std::uint32_t b : object == synthetic::Object::PencilHolder ? block_sizes : std::vector<std::uint32_t>{default_block})
      run(object, n, true, b, volume, keep, dir);
    if (quick) break;
  }
  std::filesystem::remove_all(dir);
  return 0;
}
