// Any structure into an .ivol octree file, one slab of slices at a time.
#include <algorithm>

#include "ivol/error.hpp"
#include "ivol/structures.hpp"

namespace ivol {

StreamingResult write_structure(const VoxelStructure& structure, const std::string& path, const Metadata& metadata,
                                StreamingOptions options) {
  const Dims& dims = structure.dims();
  const bool keep_fine_only = structure.kind() == StructureKind::Octree;
  StreamingOctreeWriter writer(path, dims, options);
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  std::vector<float> slab(std::uint64_t{writer.slab_slices()} * slice);
  std::vector<std::uint8_t> keep(keep_fine_only ? slab.size() : 0);
  // Bricks by their first slice, so each slab visits only the bricks it meets.
  std::vector<std::size_t> order(structure.bricks().size());
  for (std::size_t b = 0; b < order.size(); ++b) order[b] = b;
  const auto& bricks = structure.bricks();
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return bricks[a].origin[2] < bricks[b].origin[2]; });
  std::vector<std::size_t> open;  // bricks that reach into the current slab
  std::size_t next = 0;
  const auto& values = structure.values();
  while (writer.next_slab_count() > 0) {
    const std::uint64_t z0 = writer.next_slab_first();
    const std::uint64_t z1 = z0 + writer.next_slab_count();
    while (next < order.size() && bricks[order[next]].origin[2] < z1) open.push_back(order[next++]);
    for (std::size_t n = 0; n < open.size();) {
      const Brick& b = bricks[open[n]];
      const bool fine = b.voxel[0] == 1 && b.voxel[1] == 1 && b.voxel[2] == 1;
      for (std::uint32_t k = 0; k < b.count[2]; ++k) {
        const std::uint64_t bz0 = b.origin[2] + std::uint64_t{k} * b.voxel[2];
        const std::uint64_t bz1 = std::min<std::uint64_t>(dims[2], bz0 + b.voxel[2]);
        if (bz1 <= z0 || bz0 >= z1) continue;
        for (std::uint32_t j = 0; j < b.count[1]; ++j) {
          const std::uint64_t y0 = b.origin[1] + std::uint64_t{j} * b.voxel[1];
          const std::uint64_t y1 = std::min<std::uint64_t>(dims[1], y0 + b.voxel[1]);
          for (std::uint32_t i = 0; i < b.count[0]; ++i) {
            const std::uint64_t x0 = b.origin[0] + std::uint64_t{i} * b.voxel[0];
            const std::uint64_t x1 = std::min<std::uint64_t>(dims[0], x0 + b.voxel[0]);
            const float v = values[b.first_value + (std::uint64_t{k} * b.count[1] + j) * b.count[0] + i];
            for (std::uint64_t z = std::max(bz0, z0); z < std::min(bz1, z1); ++z)
              for (std::uint64_t y = y0; y < y1; ++y) {
                const std::uint64_t row = ((z - z0) * dims[1] + y) * dims[0];
                std::fill(slab.begin() + static_cast<std::ptrdiff_t>(row + x0),
                          slab.begin() + static_cast<std::ptrdiff_t>(row + x1), v);
                if (keep_fine_only)
                  std::fill(keep.begin() + static_cast<std::ptrdiff_t>(row + x0),
                            keep.begin() + static_cast<std::ptrdiff_t>(row + x1), fine ? 1 : 0);
              }
          }
        }
      }
      // A brick that ends within this slab is done.
      if (b.origin[2] + std::uint64_t{b.voxel[2]} * b.count[2] <= z1) {
        open[n] = open.back();
        open.pop_back();
      } else {
        ++n;
      }
    }
    writer.add_slab(slab.data(), keep_fine_only ? keep.data() : nullptr);
  }
  return writer.finish(metadata);
}

}  // namespace ivol
