// The paper's Tables 1-3 at this machine's scale: for industrial-like
// phantoms, the dense regular FDK against FDK straight into each structure —
// structure generation time, total time, memory, file size, speedup, and the
// error against the dense reconstruction.
//
//   recon_bench [--size N] [--views V] [--detector D] [--phantom NAME]...
//               [--structure KIND]... [--device-memory MIB] [--margin M]
//               [--rule preview|detection]... [--detection-scale S]
//               [--detection-margin M] [--detection-thinning T] [--detection-factor F]
//
// Default: 256³ voxels from 360 views of 384² pixels, all five industrial
// phantoms, all four structures, both refinement rules side by side (the
// old one: half of Otsu's threshold on a 1/4 preview, margin 2; the
// detection rule: docs/refinement.md). Prints one JSON line per run.
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
  std::vector<std::string> rules;
  DetectionRule detection_rule;  // recon's defaults unless given
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
    else if (arg == "--rule")
      rules.push_back(next());
    else if (arg == "--detection-scale")
      detection_rule.otsu_share = std::stod(next());
    else if (arg == "--detection-margin")
      detection_rule.margin = static_cast<unsigned>(std::stoul(next()));
    else if (arg == "--detection-thinning")
      detection_rule.thinning = static_cast<unsigned>(std::stoul(next()));
    else if (arg == "--detection-factor")
      detection_rule.factor = static_cast<unsigned>(std::stoul(next()));
    else {
      std::fprintf(stderr,
                   "usage: recon_bench [--size N] [--views V] [--detector D] [--phantom NAME]... "
                   "[--structure KIND]... [--margin M] [--device-memory MIB] [--rule preview|detection]... "
                   "[--detection-scale S] [--detection-margin M] [--detection-thinning T] [--detection-factor F]\n");
      return 1;
    }
  }
  if (phantoms.empty()) phantoms = {"pencil-holder", "connector-board", "computer-board", "thin-pipe", "lattice-part"};
  if (structures.empty()) structures = {"regular", "rectilinear", "nested", "octree"};
  if (rules.empty()) rules = {"preview", "detection"};
  for (const std::string& rule : rules)
    if (rule != "preview" && rule != "detection") {
      std::fprintf(stderr, "recon_bench: --rule is preview or detection, not %s\n", rule.c_str());
      return 1;
    }

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
    // The object: dense voxels above Otsu's threshold of the dense
    // reconstruction itself, the same for every rule and structure.
    const float object_threshold = otsu_threshold(dense.data(), dense.size());
    // The phantom's own density at the voxel centres, to
    // tell a missed object voxel on the part from one in a streak in air.
    std::vector<float> material(voxels);
    voxelize(phantom, grid, 0, size, material.data());
    auto near_material = [&](std::uint64_t index) {
      const auto x = static_cast<std::int64_t>(index % size), y = static_cast<std::int64_t>(index / size % size),
                 z = static_cast<std::int64_t>(index / size / size);
      const std::int64_t n = size;
      for (std::int64_t c = std::max<std::int64_t>(z - 2, 0); c <= std::min(z + 2, n - 1); ++c)
        for (std::int64_t b = std::max<std::int64_t>(y - 2, 0); b <= std::min(y + 2, n - 1); ++b)
          for (std::int64_t a = std::max<std::int64_t>(x - 2, 0); a <= std::min(x + 2, n - 1); ++a)
            if (material[static_cast<std::size_t>((c * n + b) * n + a)] > 0) return true;
      return false;
    };

    for (const std::string& kind_name : structures)
      for (const std::string& rule : rules) {
        StructureKind kind{};
        parse_structure(kind_name, kind);
        const auto start = std::chrono::steady_clock::now();
        // Generation: low-resolution FDK, Otsu's threshold, need mask,
        // structure. The old rule: a 1/4 preview of a thinned scan, each cell
        // its centre's value, half of Otsu's threshold, a margin. The
        // detection rule: each 1/4 cell the largest of its 2³ samples at 1/2.
        const bool detection = rule == "detection";
        const Preview preview_result =
            detection ? reconstruct_detection_preview(projections, geometry, options, grid, detection_rule.factor,
                                                      detection_rule.thinning, detection_rule.margin)
                      : reconstruct_preview(projections, geometry, options, grid, factor);
        const VolumeGrid& low = preview_result.grid;
        const std::vector<float>& preview = preview_result.values;
        const double preview_seconds = since(start);
        const auto generation_start = std::chrono::steady_clock::now();
        const float otsu = preview_result.otsu_threshold;
        const float threshold = static_cast<float>(otsu * (detection ? detection_rule.otsu_share : threshold_scale));
        const unsigned rule_margin = detection ? 0 : margin;  // the detection rule pools over its margin
        const NeedMask mask = need_mask_from_low_resolution(preview.data(), Dims{low.size[0], low.size[1], low.size[2]},
                                                            detection ? detection_rule.factor : factor,
                                                            Dims{size, size, size}, threshold, rule_margin);
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
        double object_error = 0, all_error = 0;
        std::uint64_t object_voxels = 0, object_exact = 0, missed_near_material = 0;
        for (std::uint64_t i = 0; i < voxels; ++i) {
          const double e = std::abs(static_cast<double>(back[i]) - dense[i]);
          all_error += e;
          if (dense[i] > object_threshold) {
            object_error = std::max(object_error, e);
            ++object_voxels;
            object_exact += e == 0.0;
            if (e != 0.0) missed_near_material += near_material(i);
          }
        }
        const double reduction = static_cast<double>(voxels) / static_cast<double>(structure->voxel_count());
        const double total = reconstruction_seconds + writing_seconds;
        std::printf(
            "{\"phantom\": \"%s\", \"structure\": \"%s\", \"rule\": \"%s\", \"voxels\": %llu, \"voxel_reduction\": "
            "%.2f, "
            "\"preview_s\": %.3f, \"generation_s\": %.3f, \"fdk_s\": %.3f, \"writing_s\": %.3f, \"total_s\": %.3f, "
            "\"generation_share\": %.3f, \"speedup_fdk\": %.2f, \"speedup_over_reduction\": %.2f, "
            "\"memory_bytes\": %llu, \"memory_reduction_vs_float32\": %.1f, \"file_bytes\": %llu, "
            "\"file_reduction_vs_float32\": %.1f, \"max_error_on_object\": %.3g, \"mean_error\": %.3g, "
            "\"object_voxels\": %llu, \"object_exact_share\": %.5f, \"object_missed\": %llu, "
            "\"object_missed_near_material\": %llu, \"threshold\": %.4g, "
            "\"object_threshold\": %.4g}\n",
            name.c_str(), kind_name.c_str(), rule.c_str(), static_cast<unsigned long long>(structure->voxel_count()),
            reduction, preview_seconds, generation_seconds, fdk.timings.total, writing_seconds, total,
            (preview_seconds + generation_seconds) / total, dense_seconds / reconstruction_seconds,
            dense_seconds / reconstruction_seconds / reduction,
            static_cast<unsigned long long>(structure->memory().total()),
            static_cast<double>(voxels * 4) / static_cast<double>(structure->memory().total()),
            static_cast<unsigned long long>(written.write.file_bytes),
            static_cast<double>(voxels * 4) / static_cast<double>(written.write.file_bytes), object_error,
            all_error / static_cast<double>(voxels), static_cast<unsigned long long>(object_voxels),
            static_cast<double>(object_exact) / static_cast<double>(std::max<std::uint64_t>(object_voxels, 1)),
            static_cast<unsigned long long>(object_voxels - object_exact),
            static_cast<unsigned long long>(missed_near_material), threshold, object_threshold);
        std::fflush(stdout);
      }
  }
  return 0;
}
