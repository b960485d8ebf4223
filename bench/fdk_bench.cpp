// FDK throughput: backprojection GUPS (voxel updates per second) and
// end-to-end time of a dense reconstruction from analytic projections.
//
//   fdk_bench [--size N] [--views V] [--detector D] [--phantom NAME]
//             [--device I] [--export DIR] [--backprojector default|opencl|both]
//
// --backprojector opencl keeps the OpenCL kernel on a CPU device (no native
// backprojection); both reconstructs the same projections with the kernel
// and then with the default (native on a CPU with AVX-512), prints a line
// for each, the ratio of their GUPS and whether their volumes are bit-equal.
//
// Default: 256³ voxels of 1 mm from 360 views of 384² pixels of 1.6 mm,
// SID/SDD 600/1200 mm. --export writes the projections (float32, views ×
// rows × columns), RTK's geometry XML and our volume to DIR so that
// bench/rtk/rtk_fdk.py can reconstruct the same scan side by side.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"

using namespace ivol::recon;

namespace {

void write_floats(const std::string& path, const float* data, std::size_t count) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(count * sizeof(float)));
  if (!out) {
    std::fprintf(stderr, "fdk_bench: cannot write %s\n", path.c_str());
    std::exit(2);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::uint32_t size = 256;
  std::size_t views = 360;
  int detector = 384;
  std::string phantom_name = "shepp-logan";
  std::string export_dir;
  std::string backprojector = "default";
  FdkOptions options;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto next = [&]() -> std::string {
      if (a + 1 >= argc) {
        std::fprintf(stderr, "fdk_bench: %s needs a value\n", arg.c_str());
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
      phantom_name = next();
    else if (arg == "--device")
      options.devices.push_back(std::stoi(next()));
    else if (arg == "--export")
      export_dir = next();
    else if (arg == "--backprojector")
      backprojector = next();
    else {
      std::fprintf(
          stderr,
          "usage: fdk_bench [--size N] [--views V] [--detector D] [--phantom NAME] [--device I] [--export DIR] "
          "[--backprojector default|opencl|both]\n");
      return 1;
    }
  }
  if (backprojector != "default" && backprojector != "opencl" && backprojector != "both") {
    std::fprintf(stderr, "fdk_bench: --backprojector must be default, opencl or both, not '%s'\n",
                 backprojector.c_str());
    return 1;
  }
  // The detector sees the whole volume at magnification 2 with 20 % spare.
  const double voxel = 1.0;
  const double pitch = 2.0 * size * voxel * 1.2 / detector;
  const ScanGeometry geometry = circular_scan({detector, detector, pitch, pitch}, views, 600.0, 1200.0, 2 * M_PI);
  const VolumeGrid grid = VolumeGrid::centred({size, size, size}, voxel);
  const Phantom phantom = named_phantom(phantom_name, 0.5 * size * voxel);

  auto t0 = std::chrono::steady_clock::now();
  InMemoryProjections projections = project_scan(phantom, geometry);
  const double projecting = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::vector<float> volume(grid.voxel_count());
  const std::size_t slice = std::size_t{size} * size;
  auto run = [&](bool native) {
    FdkOptions chosen = options;
    chosen.native_cpu_backprojection = native;
    const FdkReport report = reconstruct_fdk(projections, geometry, grid, chosen,
                                             [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
                                               std::copy(data, data + slice * (k1 - k0), volume.data() + slice * k0);
                                             });
    std::printf(
        "{\"size\": %u, \"views\": %zu, \"detector\": %d, \"phantom\": \"%s\", \"device\": \"%s\", "
        "\"backprojector\": \"%s\", \"slabs\": %zu, \"projecting_s\": %.3f, \"setup_s\": %.3f, \"reading_s\": %.3f, "
        "\"filtering_s\": %.3f, \"backprojection_s\": %.3f, \"transfer_s\": %.3f, \"total_s\": %.3f, \"gups\": %.3f}\n",
        size, views, detector, phantom_name.c_str(), report.devices.empty() ? "" : report.devices[0].c_str(),
        report.backprojectors.empty() ? "" : report.backprojectors[0].c_str(), report.slab_count, projecting,
        report.timings.setup, report.timings.reading, report.timings.filtering, report.timings.backprojection,
        report.timings.transfer, report.timings.total, report.gups());
    std::fflush(stdout);
    return report.gups();
  };
  if (backprojector == "both") {
    const double kernel_gups = run(false);
    const std::vector<float> kernel_volume = volume;
    const double default_gups = run(true);
    const bool same = std::memcmp(kernel_volume.data(), volume.data(), volume.size() * sizeof(float)) == 0;
    std::printf("{\"gups_ratio\": %.2f, \"same_bits\": %s}\n", default_gups / kernel_gups, same ? "true" : "false");
  } else {
    run(backprojector == "default");
  }
  if (!export_dir.empty()) {
    write_floats(export_dir + "/projections.raw", projections.data().data(), projections.data().size());
    write_floats(export_dir + "/ivol_volume.raw", volume.data(), volume.size());
    const double origin = -0.5 * (detector - 1) * pitch;
    write_rtk_geometry_xml(export_dir + "/geometry.xml", geometry, origin, origin);
    std::printf("exported to %s (pitch %.6f mm)\n", export_dir.c_str(), pitch);
  }
  return 0;
}
