// structures_bench: the paper's Table 1 at this machine's scale — for
// industrial-like objects, the voxels, memory, file size and generation time
// of the regular, rectilinear, nested and octree structures.
//
// The need mask comes from a 1/4-resolution volume (the box-filtered
// synthetic volume standing in for the paper's low-resolution
// reconstruction), thresholded at half the material's attenuation and grown
// by a 3-voxel margin. File sizes: binary16 values, zstd; the rectilinear and
// nested structures have no format of their own yet and are written as
// lossless octree files of their voxels.
//
//   structures_bench [--size N] [--quick]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "ivol/structures.hpp"
#include "synthetic_volume.hpp"

namespace {

using namespace ivol;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::vector<float> downsample(const std::vector<float>& v, const Dims& d, std::uint32_t f, Dims& out) {
  out = {(d[0] + f - 1) / f, (d[1] + f - 1) / f, (d[2] + f - 1) / f};
  std::vector<double> sum(voxel_count(out), 0.0);
  std::vector<std::uint32_t> count(sum.size(), 0);
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x) {
        const std::uint64_t c = (std::uint64_t{z / f} * out[1] + y / f) * out[0] + x / f;
        sum[c] += v[(std::uint64_t{z} * d[1] + y) * d[0] + x];
        ++count[c];
      }
  std::vector<float> low(sum.size());
  for (std::size_t i = 0; i < low.size(); ++i) low[i] = static_cast<float>(sum[i] / count[i]);
  return low;
}

}  // namespace

int main(int argc, char** argv) {
  std::uint32_t n = 512;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--size") && i + 1 < argc) n = static_cast<std::uint32_t>(std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--quick")) n = 128;
    else {
      std::fprintf(stderr, "usage: structures_bench [--size N] [--quick]\n");
      return 1;
    }
  }
  const std::string dir = std::filesystem::temp_directory_path() / "ivol-structures-bench";
  std::filesystem::create_directories(dir);
  std::printf("structures_bench: %u^3 voxels; need mask from a 1/4-resolution volume, threshold 0.025/mm, margin 3\n\n", n);
  std::printf("| object | structure | voxels | of dense | memory MiB | vs dense f32 | file MiB | vs dense f32 | generation s |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (synthetic::Object object : {synthetic::Object::PencilHolder, synthetic::Object::Board, synthetic::Object::Pipe}) {
    synthetic::VolumeSpec spec;
    spec.dims = {n, n, n};
    spec.object = object;
    const std::vector<float> volume = synthetic::make_volume(spec);
    Dims low_dims;
    const std::vector<float> low = downsample(volume, spec.dims, 4, low_dims);
    const double dense32 = 4.0 * voxel_count(spec.dims);
    auto t = Clock::now();
    const NeedMask mask = need_mask_from_low_resolution(low.data(), low_dims, 4, spec.dims, spec.material / 2, 3);
    const double mask_seconds = since(t);
    for (StructureKind kind : {StructureKind::Regular, StructureKind::Rectilinear, StructureKind::Nested,
                               StructureKind::Octree}) {
      t = Clock::now();
      auto s = generate_structure(kind, mask);
      const double generation = since(t) + mask_seconds;
      s->sample_dense(volume.data());
      const std::string path = dir + "/s.ivol";
      StreamingOptions options;
      const std::uint64_t file = write_structure(*s, path, Metadata{}, options).write.file_bytes;
      std::printf("| %s | %s | %llu | %.1f %% | %.1f | %.1fx | %.2f | %.1fx | %.3f |\n", synthetic::object_name(object),
                  structure_name(kind), static_cast<unsigned long long>(s->voxel_count()),
                  100.0 * s->voxel_count() / voxel_count(spec.dims), s->memory().total() / 1048576.0,
                  dense32 / s->memory().total(), file / 1048576.0, dense32 / file, generation);
      std::fflush(stdout);
    }
  }
  std::filesystem::remove_all(dir);

  // Generation alone, for volumes too large to hold here: the need mask comes
  // from a synthetic 1/4-resolution volume directly. The paper's generation
  // took 43.9 of 55 minutes at 4000^3.
  std::printf("\n| object | full resolution | mask cells | kept voxels | mask s | octree s (1 thread) | octree s (all) | nested s | rectilinear s |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (std::uint32_t full : {n, 2 * n, 4 * n}) {
    synthetic::VolumeSpec spec;
    spec.dims = {full / 4, full / 4, full / 4};
    spec.object = synthetic::Object::PencilHolder;
    const std::vector<float> low = synthetic::make_volume(spec);
    const Dims full_dims{full, full, full};
    auto t = Clock::now();
    const NeedMask mask = need_mask_from_low_resolution(low.data(), spec.dims, 4, full_dims, spec.material / 2, 3);
    const double mask_s = since(t);
    GenerationOptions one;
    one.threads = 1;
    t = Clock::now();
    generate_structure(StructureKind::Octree, mask, one);
    const double one_s = since(t);
    t = Clock::now();
    const auto b = generate_structure(StructureKind::Octree, mask);
    const double all_s = since(t);
    t = Clock::now();
    generate_structure(StructureKind::Nested, mask);
    const double nested_s = since(t);
    t = Clock::now();
    generate_structure(StructureKind::Rectilinear, mask);
    const double rect_s = since(t);
    std::printf("| pencil-holder | %u^3 | %u^3 | %llu | %.3f | %.3f | %.3f | %.3f | %.3f |\n", full, full / 4,
                static_cast<unsigned long long>(b->voxel_count()), mask_s, one_s, all_s, nested_s, rect_s);
    std::fflush(stdout);
  }
  return 0;
}
