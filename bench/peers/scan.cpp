#include "scan.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "ivol/recon/preview.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"
#include "ivol/structures.hpp"

namespace peers {

using namespace ivol::recon;

namespace {

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

void write_floats(const std::string& path, const float* data, std::size_t count) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(count * sizeof(float)));
  if (!out) throw std::runtime_error("cannot write " + path);
}

}  // namespace

double detector_pitch(const ScanSetup& setup) { return 2.0 * setup.size * 1.2 / setup.detector; }

ScanGeometry scan_geometry(const ScanSetup& setup) {
  const double pitch = detector_pitch(setup);
  return circular_scan({setup.detector, setup.detector, pitch, pitch}, setup.views, 600.0, 1200.0, 2 * M_PI);
}

VolumeGrid volume_grid(const ScanSetup& setup) {
  return VolumeGrid::centred({setup.size, setup.size, setup.size}, 1.0);
}

InMemoryProjections noisy_scan(const std::string& phantom, const ScanSetup& setup) {
  InMemoryProjections projections = project_scan(named_phantom(phantom, 0.5 * setup.size), scan_geometry(setup));
  add_poisson_noise(projections.data().data(), projections.data().size(), setup.photons, setup.seed);
  return projections;
}

std::vector<float> reconstructed_volume(const std::string& phantom, const ScanSetup& setup,
                                        const std::string& cache_dir) {
  const std::uint64_t voxels = volume_grid(setup).voxel_count();
  char name[160];
  std::snprintf(name, sizeof name, "/recon_%s_%u_v%zu_d%d_p%.0f_s%llu.f32", phantom.c_str(), setup.size, setup.views,
                setup.detector, setup.photons, static_cast<unsigned long long>(setup.seed));
  const std::string path = cache_dir + name;
  std::vector<float> volume(voxels);
  if (std::filesystem::exists(path) && std::filesystem::file_size(path) == voxels * sizeof(float)) {
    std::ifstream in(path, std::ios::binary);
    in.read(reinterpret_cast<char*>(volume.data()), static_cast<std::streamsize>(voxels * sizeof(float)));
    if (in) return volume;
  }
  const auto start = std::chrono::steady_clock::now();
  InMemoryProjections projections = noisy_scan(phantom, setup);
  const std::size_t slice = std::size_t{setup.size} * setup.size;
  reconstruct_fdk(projections, scan_geometry(setup), volume_grid(setup), FdkOptions{},
                  [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
                    std::copy(data, data + slice * (k1 - k0), volume.data() + slice * k0);
                  });
  std::fprintf(stderr, "peers_bench: scanned and reconstructed %s at %u^3 in %.1f s (cached in %s)\n", phantom.c_str(),
               setup.size, since(start), path.c_str());
  std::filesystem::create_directories(cache_dir);
  write_floats(path + ".tmp", volume.data(), volume.size());
  std::filesystem::rename(path + ".tmp", path);
  return volume;
}

void reconstruction_run(const std::string& phantom_name, const ScanSetup& setup, const std::string& export_dir) {
  const ScanGeometry geometry = scan_geometry(setup);
  const VolumeGrid grid = volume_grid(setup);
  const std::uint32_t n = setup.size;
  const std::uint64_t voxels = grid.voxel_count();
  const std::size_t slice = std::size_t{n} * n;
  InMemoryProjections projections = noisy_scan(phantom_name, setup);
  FdkOptions options;
  FdkReconstructor reconstructor(projections, geometry, options);

  // Dense: the whole volume; timed from the filtered projections' setup to
  // the last slab on the host, as RTK's Update() is.
  std::vector<float> dense(voxels);
  auto start = std::chrono::steady_clock::now();
  const FdkReport dense_report =
      reconstructor.reconstruct(grid, [&](std::uint32_t k0, std::uint32_t k1, const float* d) {
        std::copy(d, d + slice * (k1 - k0), dense.begin() + static_cast<std::ptrdiff_t>(slice * k0));
      });
  const double dense_seconds = since(start);

  // The paper's pipeline as `ivol recon --structure octree` runs it: a 1/4
  // preview from a thinned scan, half of Otsu's threshold, margin 2, the
  // octree, FDK into its voxels only. Writing the file is not counted (nor is
  // it for the dense run or RTK).
  const std::uint32_t factor = 4;
  start = std::chrono::steady_clock::now();
  const Preview preview = reconstruct_preview(projections, geometry, options, grid, factor);
  const double preview_seconds = since(start);
  const ivol::NeedMask mask = ivol::need_mask_from_low_resolution(
      preview.values.data(), ivol::Dims{preview.grid.size[0], preview.grid.size[1], preview.grid.size[2]}, factor,
      ivol::Dims{n, n, n}, 0.5f * preview.otsu_threshold, 2);
  auto octree = ivol::generate_structure(ivol::StructureKind::Octree, mask);
  const FdkReport octree_report = reconstructor.reconstruct_structure(grid, *octree);
  const double octree_seconds = since(start);
  const double reduction = static_cast<double>(voxels) / static_cast<double>(octree->voxel_count());

  std::filesystem::create_directories(export_dir);
  write_floats(export_dir + "/projections.raw", projections.data().data(), projections.data().size());
  const double origin = -0.5 * (setup.detector - 1) * detector_pitch(setup);
  write_rtk_geometry_xml(export_dir + "/geometry.xml", geometry, origin, origin);
  write_floats(export_dir + "/ivol_dense.raw", dense.data(), dense.size());
  std::vector<float> octree_dense(voxels);
  octree->to_dense(octree_dense.data());
  write_floats(export_dir + "/ivol_octree.raw", octree_dense.data(), octree_dense.size());
  // The analytic object, each voxel the mean of 2^3 samples.
  std::vector<float> truth(voxels);
  voxelize(named_phantom(phantom_name, 0.5 * n), grid, 0, n, truth.data(), 2);
  write_floats(export_dir + "/phantom.raw", truth.data(), truth.size());

  std::printf(
      "{\"kind\": \"recon\", \"phantom\": \"%s\", \"size\": %u, \"views\": %zu, \"detector\": %d, "
      "\"pitch\": %.9g, \"photons\": %.0f, \"dense_s\": %.3f, \"dense_backprojection_s\": %.3f, "
      "\"dense_filtering_s\": %.3f, \"dense_gups\": %.4f, \"octree_s\": %.3f, \"octree_preview_s\": %.3f, "
      "\"octree_fdk_s\": %.3f, \"octree_voxels\": %llu, \"voxel_reduction\": %.3f, \"octree_speedup\": %.3f, "
      "\"device\": \"%s\"}\n",
      phantom_name.c_str(), n, setup.views, setup.detector, detector_pitch(setup), setup.photons, dense_seconds,
      dense_report.timings.backprojection, dense_report.timings.filtering, dense_report.gups(), octree_seconds,
      preview_seconds, octree_report.timings.total, static_cast<unsigned long long>(octree->voxel_count()), reduction,
      dense_seconds / octree_seconds, dense_report.devices.empty() ? "" : dense_report.devices[0].c_str());
  std::fflush(stdout);
}

}  // namespace peers
