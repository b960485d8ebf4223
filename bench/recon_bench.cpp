// The paper's Tables 1-3 at this machine's scale: for industrial-like
// phantoms, the dense regular FDK against FDK straight into each structure —
// structure generation time, total time, memory, file size, speedup, and the
// error against the dense reconstruction.
//
//   recon_bench [--size N] [--views V] [--detector D] [--phantom NAME]...
//               [--structure KIND]... [--device-memory MIB] [--margin M]
//
// Default: 256³ voxels from 360 views of 384² pixels, all five industrial
// phantoms, all four structures. Prints one JSON line per run.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "ivol/keep_mask.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structures.hpp"

using namespace ivol;
using namespace ivol::recon;

namespace {

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::uint32_t size = 256;
  std::size_t views = 360;
  int detector = 384;
  unsigned margin = 2;
  std::uint32_t factor = 4;
  std::uint64_t device_memory_mib = 0;
  double threshold_scale = 0.5;
  std::vector<std::string> phantoms;
  std::vector<std::string> structures;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto next = [&]() -> std::string {
      if (a + 1 >= argc) {
        std::fprintf(stderr, "recon_bench: %s needs a value\n", arg.c_str());
        std::exit(1);
      }
      return argv[++a];
    };
    if (arg == "--size")
      size = static_cast<std::uint32_t>(std::stoul(next()));
    else if (arg == "--views")
      views = std::stoul(next());
    else if (arg == "--detector")
      detector = std::stoi(next());
    else if (arg == "--phantom")
      phantoms.push_back(next());
    else if (arg == "--structure")
      structures.push_back(next());
    else if (arg == "--margin")
      margin = static_cast<unsigned>(std::stoul(next()));
    else if (arg == "--device-memory")
      device_memory_mib = std::stoull(next());
    else if (arg == "--threshold-scale")
      threshold_scale = std::stod(next());
    else {
      std::fprintf(stderr,
                   "usage: recon_bench [--size N] [--views V] [--detector D] [--phantom NAME]... "
                   "[--structure KIND]... [--margin M] [--device-memory MIB]\n");
      return 1;
    }
  }
  if (phantoms.empty()) phantoms = {"pencil-holder", "connector-board", "computer-board", "thin-pipe", "lattice-part"};
  if (structures.empty()) structures = {"regular", "rectilinear", "nested", "octree"};

  const double voxel = 1.0;
  const double pitch = 2.0 * size * voxel * 1.2 / detector;
  const ScanGeometry geometry = circular_scan({detector, detector, pitch, pitch}, views, 600.0, 1200.0, 2 * M_PI);
  const VolumeGrid grid = VolumeGrid::centred({size, size, size}, voxel);
  const std::uint64_t voxels = grid.voxel_count();
  FdkOptions options;
  options.device_memory_limit = device_memory_mib << 20;
  const std::string dir = std::filesystem::temp_directory_path().string();

  for (const std::string& name : phantoms) {
    const Phantom phantom = named_phantom(name, 0.5 * size * voxel);
    InMemoryProjections projections = project_scan(phantom, geometry);
    FdkReconstructor reconstructor(projections, geometry, options);
    // The dense regular FDK: the baseline, and the reference for the errors.
    std::vector<float> dense(voxels);
    const std::size_t slice = std::size_t{size} * size;
    auto t = std::chrono::steady_clock::now();
    const FdkReport dense_report =
        reconstructor.reconstruct(grid, [&](std::uint32_t k0, std::uint32_t k1, const float* d) {
          std::copy(d, d + slice * (k1 - k0), dense.begin() + static_cast<std::ptrdiff_t>(slice * k0));
        });
    const double dense_seconds = since(t);
    std::printf(
        "{\"phantom\": \"%s\", \"structure\": \"dense\", \"size\": %u, \"views\": %zu, \"total_s\": %.3f, "
        "\"backprojection_s\": %.3f, \"filtering_s\": %.3f, \"gups\": %.3f, \"slabs\": %zu, "
        "\"memory_bytes\": %llu}\n",
        name.c_str(), size, views, dense_seconds, dense_report.timings.backprojection, dense_report.timings.filtering,
        dense_report.gups(), dense_report.slab_count, static_cast<unsigned long long>(voxels * 4));
    std::fflush(stdout);

    for (const std::string& kind_name : structures) {
      StructureKind kind{};
      parse_structure(kind_name, kind);
      const auto start = std::chrono::steady_clock::now();
      // Generation: low-resolution FDK (a thinned scan), Otsu's threshold,
      // need mask, structure.
      const Preview preview_result = reconstruct_preview(projections, geometry, options, grid, factor);
      const VolumeGrid& low = preview_result.grid;
      const std::vector<float>& preview = preview_result.values;
      const double preview_seconds = since(start);
      const auto generation_start = std::chrono::steady_clock::now();
      // Otsu's threshold on the preview, scaled (recon's default 0.5): the
      // preview averages thin walls with the air around them.
      const float otsu = preview_result.otsu_threshold;
      const float threshold = static_cast<float>(otsu * threshold_scale);
      const NeedMask mask = need_mask_from_low_resolution(preview.data(), Dims{low.size[0], low.size[1], low.size[2]},
                                                          factor, Dims{size, size, size}, threshold, margin);
      auto structure = generate_structure(kind, mask);
      const double generation_seconds = since(generation_start);
      const FdkReport fdk = reconstructor.reconstruct_structure(grid, *structure);
      const double reconstruction_seconds = since(start);
      const auto write_start = std::chrono::steady_clock::now();
      const std::string path = dir + "/recon_bench_" + kind_name + ".ivol";
      Metadata metadata;
      const StreamingResult written = write_structure(*structure, path, metadata);
      const double writing_seconds = since(write_start);
      std::filesystem::remove(path);

      // Errors against the dense reconstruction: zero where the structure
      // is fine (same bits), and over the object (above the threshold).
      std::vector<float> back(voxels);
      structure->to_dense(back.data());
      // The object: dense voxels above Otsu's threshold (unscaled).
      double object_error = 0, all_error = 0;
      std::uint64_t object_voxels = 0, object_exact = 0;
      for (std::uint64_t i = 0; i < voxels; ++i) {
        const double e = std::abs(static_cast<double>(back[i]) - dense[i]);
        all_error += e;
        if (dense[i] > otsu) {
          object_error = std::max(object_error, e);
          ++object_voxels;
          object_exact += e == 0.0;
        }
      }
      const double reduction = static_cast<double>(voxels) / static_cast<double>(structure->voxel_count());
      const double total = reconstruction_seconds + writing_seconds;
      std::printf(
          "{\"phantom\": \"%s\", \"structure\": \"%s\", \"voxels\": %llu, \"voxel_reduction\": %.2f, "
          "\"preview_s\": %.3f, \"generation_s\": %.3f, \"fdk_s\": %.3f, \"writing_s\": %.3f, \"total_s\": %.3f, "
          "\"generation_share\": %.3f, \"speedup_fdk\": %.2f, \"speedup_over_reduction\": %.2f, "
          "\"memory_bytes\": %llu, \"memory_reduction_vs_float32\": %.1f, \"file_bytes\": %llu, "
          "\"file_reduction_vs_float32\": %.1f, \"max_error_on_object\": %.3g, \"mean_error\": %.3g, "
          "\"object_voxels\": %llu, \"object_exact_share\": %.5f, \"threshold\": %.4g}\n",
          name.c_str(), kind_name.c_str(), static_cast<unsigned long long>(structure->voxel_count()), reduction,
          preview_seconds, generation_seconds, fdk.timings.total, writing_seconds, total,
          (preview_seconds + generation_seconds) / total, dense_seconds / reconstruction_seconds,
          dense_seconds / reconstruction_seconds / reduction,
          static_cast<unsigned long long>(structure->memory().total()),
          static_cast<double>(voxels * 4) / static_cast<double>(structure->memory().total()),
          static_cast<unsigned long long>(written.write.file_bytes),
          static_cast<double>(voxels * 4) / static_cast<double>(written.write.file_bytes), object_error,
          all_error / static_cast<double>(voxels), static_cast<unsigned long long>(object_voxels),
          static_cast<double>(object_exact) / static_cast<double>(std::max<std::uint64_t>(object_voxels, 1)),
          threshold);
      std::fflush(stdout);
    }
  }
  return 0;
}
