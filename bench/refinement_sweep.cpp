// Which refinement rule keeps the object: for each phantom, one dense FDK
// (the reference), then the previews of both rules, each swept over
// thresholds and margins. For every setting it prints the octree's voxel
// count and the share of the object's voxels (dense above Otsu's threshold
// of the dense volume) that fall in full-resolution voxels, without running
// the structure FDK (recon_bench checks that those voxels hold the dense
// bits).
//
//   refinement_sweep [--size N] [--views V] [--detector D] [--phantom NAME]...
//
// Prints one JSON line per setting; with SWEEP_DIAG=1 also the first missed
// object voxels of each setting (position, dense value, the cell's pooled value).
// With SWEEP_POST=1, for the detection rule at 0.3: the missed object voxels
// by the edge of the coarse leaf holding them, and what a check after the
// structure FDK would catch that refines every coarse leaf whose largest
// octant sample exceeds s2 × the samples' Otsu's threshold (the octant
// samples of 2³ leaves are voxel centres, taken from the dense volume; of
// larger leaves, trilinear in the dense volume: an estimate).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ivol/keep_mask.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structures.hpp"

using namespace ivol;
using namespace ivol::recon;

int main(int argc, char** argv) {
  std::uint32_t size = 256;
  std::size_t views = 360;
  int detector = 384;
  std::vector<std::string> phantoms;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (a + 1 >= argc) {
      std::fprintf(stderr, "refinement_sweep: %s needs a value\n", arg.c_str());
      return 1;
    }
    const std::string value = argv[++a];
    if (arg == "--size")
      size = static_cast<std::uint32_t>(std::stoul(value));
    else if (arg == "--views")
      views = std::stoul(value);
    else if (arg == "--detector")
      detector = std::stoi(value);
    else if (arg == "--phantom")
      phantoms.push_back(value);
    else {
      std::fprintf(stderr, "usage: refinement_sweep [--size N] [--views V] [--detector D] [--phantom NAME]...\n");
      return 1;
    }
  }
  if (phantoms.empty())
    phantoms = {"pencil-holder", "connector-board", "computer-board", "thin-pipe", "lattice-part", "fine-wires"};
  const double pitch = 2.0 * size * 1.2 / detector;
  const ScanGeometry geometry = circular_scan({detector, detector, pitch, pitch}, views, 600.0, 1200.0, 2 * M_PI);
  const VolumeGrid grid = VolumeGrid::centred({size, size, size}, 1.0);
  const Dims full{size, size, size};
  for (const std::string& name : phantoms) {
    InMemoryProjections projections = project_scan(named_phantom(name, 0.5 * size), geometry);
    const std::vector<float> dense = reconstruct_fdk_dense(projections, geometry, grid);
    const float object_threshold = otsu_threshold(dense.data(), dense.size());
    std::uint64_t object_voxels = 0;
    for (float v : dense) object_voxels += v > object_threshold;
    // The least any rule on cells of 4³ and 2³ could keep: an octree whose
    // cells are full resolution exactly where they hold object voxels.
    for (std::uint32_t factor : {4U, 2U}) {
      NeedMask oracle;
      oracle.dims = full;
      oracle.factor = factor;
      for (int a = 0; a < 3; ++a) oracle.cells[a] = (size + factor - 1) / factor;
      oracle.need.assign(std::size_t{oracle.cells[0]} * oracle.cells[1] * oracle.cells[2], 0);
      for (std::uint32_t k = 0; k < size; ++k)
        for (std::uint32_t j = 0; j < size; ++j)
          for (std::uint32_t i = 0; i < size; ++i)
            if (dense[(std::size_t{k} * size + j) * size + i] > object_threshold)
              oracle.need[(std::size_t{k / factor} * oracle.cells[1] + j / factor) * oracle.cells[0] + i / factor] = 1;
      std::printf("{\"phantom\": \"%s\", \"rule\": \"oracle\", \"cell\": %u, \"voxels\": %llu}\n", name.c_str(), factor,
                  static_cast<unsigned long long>(generate_structure(StructureKind::Octree, oracle)->voxel_count()));
    }
    struct Setting {
      const char* rule;
      Preview preview;
      double scale;
      unsigned margin;  // the need mask's: whole cells for the old rule, 0 for the detection rule
      unsigned pooled_margin;
    };
    std::vector<Setting> settings;
    settings.push_back({"preview", reconstruct_preview(projections, geometry, {}, grid, 4), 0.5, 2, 0});
    // Cells of 4³ (two samples per axis) and of 2³ (one), margin 2 voxels.
    for (unsigned cell : {2U}) {
      const Preview p = reconstruct_detection_preview(projections, geometry, {}, grid, cell, 2, 2);
      for (double scale : {0.5, 0.4, 0.3, 0.2, 0.15})
        settings.push_back({cell == 4 ? "detection4" : "detection2", p, scale, 0, 2});
    }
    for (const Setting& c : settings) {
      const Dims low{c.preview.grid.size[0], c.preview.grid.size[1], c.preview.grid.size[2]};
      const float threshold = static_cast<float>(c.scale * c.preview.otsu_threshold);
      const NeedMask mask = need_mask_from_low_resolution(c.preview.values.data(), low, full[0] / low[0] == 2 ? 2 : 4,
                                                          full, threshold, c.margin);
      const auto octree = generate_structure(StructureKind::Octree, mask);
      std::vector<std::uint8_t> fine(dense.size(), 0);
      for (const Brick& b : octree->bricks()) {
        if (b.voxel[0] != 1 || b.voxel[1] != 1 || b.voxel[2] != 1) continue;
        for (std::uint32_t z = 0; z < b.count[2]; ++z)
          for (std::uint32_t y = 0; y < b.count[1]; ++y)
            for (std::uint32_t x = 0; x < b.count[0]; ++x)
              fine[(std::size_t{b.origin[2] + z} * size + b.origin[1] + y) * size + b.origin[0] + x] = 1;
      }
      if (std::getenv("SWEEP_POST") && c.scale > 0.29 && c.scale < 0.31) {
        auto at = [&](double x, double y, double z) {
          auto cl = [&](double v) { return std::min(std::max(v, 0.0), size - 1.0); };
          x = cl(x);
          y = cl(y);
          z = cl(z);
          const std::size_t x0 = static_cast<std::size_t>(x), y0 = static_cast<std::size_t>(y),
                            z0 = static_cast<std::size_t>(z);
          const std::size_t x1 = std::min<std::size_t>(x0 + 1, size - 1), y1 = std::min<std::size_t>(y0 + 1, size - 1),
                            z1 = std::min<std::size_t>(z0 + 1, size - 1);
          const double fx = x - x0, fy = y - y0, fz = z - z0;
          auto d = [&](std::size_t i, std::size_t j, std::size_t k) {
            return static_cast<double>(dense[(k * size + j) * size + i]);
          };
          const double a = d(x0, y0, z0) * (1 - fx) + d(x1, y0, z0) * fx,
                       b = d(x0, y1, z0) * (1 - fx) + d(x1, y1, z0) * fx;
          const double e = d(x0, y0, z1) * (1 - fx) + d(x1, y0, z1) * fx,
                       g = d(x0, y1, z1) * (1 - fx) + d(x1, y1, z1) * fx;
          return ((a * (1 - fy) + b * fy) * (1 - fz) + (e * (1 - fy) + g * fy) * fz);
        };
        std::vector<std::uint16_t> edge_of(dense.size(), 1);
        std::vector<float> leaf_max(dense.size(), 0.0F);
        for (const Brick& b : octree->bricks()) {
          if (b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1) continue;
          for (std::uint32_t cz = 0; cz < b.count[2]; ++cz)
            for (std::uint32_t cy = 0; cy < b.count[1]; ++cy)
              for (std::uint32_t cx = 0; cx < b.count[0]; ++cx) {
                const double ox = b.origin[0] + cx * double(b.voxel[0]), oy = b.origin[1] + cy * double(b.voxel[1]),
                             oz = b.origin[2] + cz * double(b.voxel[2]);
                double m = -1e30;
                for (int o = 0; o < 8; ++o)
                  m = std::max(m, at(ox + ((o & 1) ? 0.75 : 0.25) * b.voxel[0] - 0.5,
                                     oy + ((o & 2) ? 0.75 : 0.25) * b.voxel[1] - 0.5,
                                     oz + ((o & 4) ? 0.75 : 0.25) * b.voxel[2] - 0.5));
                for (std::uint32_t z = 0; z < b.voxel[2]; ++z)
                  for (std::uint32_t y = 0; y < b.voxel[1]; ++y)
                    for (std::uint32_t x = 0; x < b.voxel[0]; ++x) {
                      const std::size_t i = (std::size_t{static_cast<std::uint32_t>(oz) + z} * size +
                                             static_cast<std::uint32_t>(oy) + y) *
                                                size +
                                            static_cast<std::uint32_t>(ox) + x;
                      if (i >= dense.size()) continue;
                      edge_of[i] = static_cast<std::uint16_t>(b.voxel[0]);
                      leaf_max[i] = static_cast<float>(m);
                    }
              }
        }
        std::uint64_t by_edge[64] = {};
        for (std::size_t i = 0; i < dense.size(); ++i)
          if (dense[i] > object_threshold && !fine[i]) ++by_edge[std::min<int>(edge_of[i], 63)];
        std::printf("post %s missed-by-edge:", name.c_str());
        for (int e = 2; e < 64; e *= 2) std::printf(" %d:%llu", e, (unsigned long long)by_edge[e]);
        std::printf("  (samples otsu %.4g, dense otsu %.4g)\n", c.preview.otsu_threshold, object_threshold);
        for (double s2 : {0.3, 0.5, 0.7, 0.9, 1.0}) {
          const float t2 = static_cast<float>(s2 * c.preview.otsu_threshold);
          std::uint64_t added = 0, left = 0, added_e2 = 0;
          for (std::size_t i = 0; i < dense.size(); ++i) {
            const bool flagged = !fine[i] && leaf_max[i] > t2;
            if (flagged) {
              ++added;
              if (edge_of[i] == 2) ++added_e2;
            }
            if (dense[i] > object_threshold && !fine[i] && !flagged) ++left;
          }
          std::printf("post %s s2 %.1f: voxels flagged %llu (edge2 %llu), octree voxels %llu, missed left %llu\n",
                      name.c_str(), s2, (unsigned long long)added, (unsigned long long)added_e2,
                      (unsigned long long)octree->voxel_count(), (unsigned long long)left);
        }
      }
      std::uint64_t kept = 0;
      int shown = 0;
      for (std::size_t i = 0; i < dense.size(); ++i) {
        kept += dense[i] > object_threshold && fine[i];
        if (std::getenv("SWEEP_DIAG") && dense[i] > object_threshold && !fine[i] && shown++ < 12) {
          const std::size_t x = i % size, y = i / size % size, z = i / size / size;
          const std::size_t f = full[0] / low[0];
          std::printf("missed %zu %zu %zu dense %.4g (T %.4g) cell %.4g (thr %.4g)\n", x, y, z, dense[i],
                      object_threshold, c.preview.values[(z / f * low[1] + y / f) * low[0] + x / f], threshold);
        }
      }
      std::printf(
          "{\"phantom\": \"%s\", \"rule\": \"%s\", \"scale\": %.2f, \"margin\": %u, \"pooled_margin\": %u, "
          "\"voxels\": %llu, \"object_voxels\": %llu, \"object_fine_share\": %.5f, \"missed\": %llu, "
          "\"preview_s\": %.2f}\n",
          name.c_str(), c.rule, c.scale, c.margin, c.pooled_margin,
          static_cast<unsigned long long>(octree->voxel_count()), static_cast<unsigned long long>(object_voxels),
          static_cast<double>(kept) / static_cast<double>(object_voxels),
          static_cast<unsigned long long>(object_voxels - kept), c.preview.seconds);
      std::fflush(stdout);
    }
  }
  return 0;
}
