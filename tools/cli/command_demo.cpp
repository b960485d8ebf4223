// ivol demo: the paper's pipeline end to end on a simulated scan. Projects an
// industrial phantom (exact line integrals, photon noise), reconstructs it
// densely and straight into an octree (a half-resolution detection preview
// finds the object, as ivol recon's default rule does; only the octree's
// voxels are backprojected), writes both as .ivol,
// and prints the paper's comparison: time, memory, file size, speedup, error.
// A slice of each is written as PNG, the octree's with its leaf borders.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "commands.hpp"
#include "ivol/keep_mask.hpp"
#include "ivol/reader.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structures.hpp"
#include "ivol_io.hpp"
#include "recon_slabs.hpp"
#include "report.hpp"
#include "signal_cleanup.hpp"
#include "slice_image.hpp"

namespace ivol::cli {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

struct DemoSettings {
  std::uint32_t size = 256;
  std::size_t views = 360;
  std::string object = "pencil-holder";
  double photons = 1e5;
  unsigned margin = 2;
  std::string output_dir = "ivol-demo";
};

struct Errors {
  double object_max_vs_dense = 0;  // over voxels above the threshold
  double object_mae_vs_truth = 0;
  std::uint64_t object_voxels = 0;
  std::uint64_t object_equal_to_dense = 0;
};

// Compares a file with the dense file and the phantom, slab by slab, over
// the object: the voxels whose centre lies in the phantom's material.
Errors compare(Reader& file, Reader& dense, const recon::Phantom& phantom, const recon::VolumeGrid& grid) {
  Errors e;
  const std::uint32_t slab = 16;
  std::vector<float> truth(std::size_t{grid.size[0]} * grid.size[1] * slab);
  for (std::uint32_t z = 0; z < grid.size[2]; z += slab) {
    const std::uint32_t end = std::min(grid.size[2], z + slab);
    const Box box{{0, 0, z}, {grid.size[0], grid.size[1], end}};
    const std::vector<float> a = file.read_box(box);
    const std::vector<float> d = dense.read_box(box);
    recon::voxelize(phantom, grid, z, end, truth.data());
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (!(truth[i] > 0.0F)) continue;
      e.object_max_vs_dense = std::max(e.object_max_vs_dense, std::abs(static_cast<double>(a[i]) - d[i]));
      e.object_equal_to_dense += a[i] == d[i];
      e.object_mae_vs_truth += std::abs(static_cast<double>(a[i]) - truth[i]);
      ++e.object_voxels;
    }
  }
  e.object_mae_vs_truth /= static_cast<double>(std::max<std::uint64_t>(e.object_voxels, 1));
  return e;
}

void write_slice(const std::string& file, const std::string& png, std::uint32_t z, bool borders) {
  Reader reader(file);
  const SliceImage slice = render_slice(reader, 2, z, 0, std::array<double, 2>{0.0, 0.06}, borders);
  write_png(slice.image, png);
}

}  // namespace

Runner add_demo_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "demo", "Simulate a CT scan, reconstruct it dense and as an octree, compare (Betz et al.'s pipeline)");
  auto s = std::make_shared<DemoSettings>();
  cmd->add_option("--size", s->size, "Voxels per side (1 mm each)")
      ->check(CLI::Range(16u, 1024u))
      ->capture_default_str();
  cmd->add_option("--views", s->views, "Projections over 360°")->check(CLI::Range(8, 10000))->capture_default_str();
  cmd->add_option("--object", s->object, "The phantom")
      ->check(CLI::IsMember(recon::phantom_names()))
      ->capture_default_str();
  cmd->add_option("--photons", s->photons, "Photons per detector pixel (0: no noise)")->capture_default_str();
  cmd->add_option("--margin", s->margin, "Full-resolution voxels kept around the object")->capture_default_str();
  cmd->add_option("-o,--output-dir", s->output_dir, "Where the files go")->capture_default_str();

  return [s, &global]() {
    const std::uint32_t n = s->size;
    const double radius = 0.5 * n;  // mm, voxels of 1 mm
    const recon::Phantom phantom = recon::named_phantom(s->object, radius);
    // SID/SDD 600/1200 mm; the detector sees the field at magnification 2.
    const int detector = static_cast<int>(std::lround(1.5 * n));
    const double pitch = 2.0 * 2.0 * radius * 1.1 / detector;
    const recon::ScanGeometry geometry =
        recon::circular_scan({detector, detector, pitch, pitch}, s->views, 600.0, 1200.0, 2 * M_PI);
    const recon::VolumeGrid grid = recon::VolumeGrid::centred({n, n, n}, 1.0);
    std::filesystem::create_directories(s->output_dir);
    const std::string dense_path = s->output_dir + "/demo-dense.ivol";
    const std::string octree_path = s->output_dir + "/demo-octree.ivol";
    for (const char* name : {"demo-dense.ivol", "demo-octree.ivol", "demo-dense-slice.png", "demo-octree-slice.png"})
      remove_temporaries_on_signal(s->output_dir + "/" + name);

    auto start = Clock::now();
    recon::InMemoryProjections projections = recon::project_scan(phantom, geometry);
    if (s->photons > 0) recon::add_poisson_noise(projections.data().data(), projections.data().size(), s->photons, 1);
    const double simulating = seconds_since(start);
    recon::FdkReconstructor reconstructor(projections, geometry);
    Metadata metadata;
    metadata.provenance = default_provenance();
    metadata.provenance["command"] = "ivol demo";
    metadata.provenance["simulation"] = {{"phantom", s->object}, {"views", s->views}, {"photons", s->photons}};
    metadata.quantity = "linear_attenuation";
    metadata.value_unit = "1/mm";

    // Dense: every voxel, written slab by slab as it is reconstructed.
    start = Clock::now();
    convert::ReconstructionSlabs slabs(reconstructor, grid, 0);  // no keep rule
    convert::ImportOptions dense_options;
    dense_options.encoding = ValueEncoding::Binary16;
    dense_options.metadata = metadata;
    const convert::ImportReport dense_written = convert::import_to_ivol(slabs, dense_path, dense_options);
    const double dense_seconds = seconds_since(start);

    // Octree: preview, structure, FDK into its voxels only, write.
    start = Clock::now();
    // The refinement rule ivol recon uses by default (docs/refinement.md):
    // cells of 2³ that the largest nearby sample of a half-resolution
    // detection preview marks.
    recon::DetectionMaskOptions detection;
    detection.margin_voxels = s->margin;
    const recon::DetectionMask found = recon::detect_need_mask(projections, geometry, {}, grid, detection);
    const auto generation_start = Clock::now();
    auto octree = generate_structure(StructureKind::Octree, found.mask);
    const double generating = seconds_since(generation_start);
    reconstructor.reconstruct_structure(grid, *octree);
    Metadata octree_metadata = metadata;
    octree_metadata.voxel_size = grid.voxel_size;
    octree_metadata.origin = grid.origin;
    const StreamingResult octree_written = write_structure(*octree, octree_path, octree_metadata);
    const double octree_seconds = seconds_since(start);

    Reader dense_file(dense_path), octree_file(octree_path);
    const Errors dense_errors = compare(dense_file, dense_file, phantom, grid);
    const Errors octree_errors = compare(octree_file, dense_file, phantom, grid);
    write_slice(dense_path, s->output_dir + "/demo-dense-slice.png", n / 2, false);
    write_slice(octree_path, s->output_dir + "/demo-octree-slice.png", n / 2, true);

    if (global.quiet) return kExitOk;
    const std::uint64_t dense_f32 = grid.voxel_count() * 4;
    std::printf(
        "ivol demo: %s, %u^3 voxels of 1 mm, %zu views of %dx%d pixels, %.0f photons/pixel "
        "(simulated in %.2f s) on %s\n\n",
        s->object.c_str(), n, s->views, detector, detector, s->photons, simulating,
        reconstructor.device_names().front().c_str());
    std::printf("  %-7s %12s %9s %13s %11s %9s %12s %11s %15s %17s\n", "", "voxels", "time s", "speedup", "memory",
                "file", "vs f32", "= dense", "max |Δ| dense", "MAE vs phantom");
    std::printf("  %-7s %12llu %9.2f %13s %11s %9s %11.1fx %10.2f%% %15s %17.2e\n", "dense",
                static_cast<unsigned long long>(grid.voxel_count()), dense_seconds, "1.0x",
                human_bytes(dense_f32).c_str(), human_bytes(dense_written.file_bytes).c_str(),
                static_cast<double>(dense_f32) / static_cast<double>(dense_written.file_bytes), 100.0, "0",
                dense_errors.object_mae_vs_truth);
    char speedup[64];
    std::snprintf(speedup, sizeof speedup, "%.1fx (%.1fx)", dense_seconds / octree_seconds,
                  static_cast<double>(grid.voxel_count()) / static_cast<double>(octree->voxel_count()));
    char max_error[32];
    std::snprintf(max_error, sizeof max_error, "%.2e", octree_errors.object_max_vs_dense);
    std::printf("  %-7s %12llu %9.2f %13s %11s %9s %11.1fx %10.2f%% %15s %17.2e\n", "octree",
                static_cast<unsigned long long>(octree->voxel_count()), octree_seconds, speedup,
                human_bytes(octree->memory().total()).c_str(), human_bytes(octree_written.write.file_bytes).c_str(),
                static_cast<double>(dense_f32) / static_cast<double>(octree_written.write.file_bytes),
                100.0 * static_cast<double>(octree_errors.object_equal_to_dense) /
                    static_cast<double>(std::max<std::uint64_t>(octree_errors.object_voxels, 1)),
                max_error, octree_errors.object_mae_vs_truth);
    std::printf(
        "\n  speedup: dense time over octree time (in brackets: the voxel reduction); memory: dense float32 "
        "against the octree as the paper holds it (16-bit values, node words); = dense: object voxels "
        "holding exactly the dense file's value; errors over the %llu object voxels (centres inside the "
        "phantom's material), in 1/mm.\n  octree time: preview %.2f s, structure generation "
        "%.3f s, FDK into the octree and writing the rest.\n  slices: %s/demo-dense-slice.png, "
        "%s/demo-octree-slice.png (octree leaves in red)\n",
        static_cast<unsigned long long>(octree_errors.object_voxels), found.seconds, generating,
        s->output_dir.c_str(), s->output_dir.c_str());
    return kExitOk;
  };
}

}  // namespace ivol::cli
