// Any structure into an .ivol octree file, one slab of slices at a time.
#include <algorithm>

#include "brick_rows.hpp"
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
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return bricks[a].origin[2] < bricks[b].origin[2]; });
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
      detail::for_each_brick_row(
          b, dims, z0, z1, [&](std::uint64_t v, std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint64_t z) {
            const auto row = static_cast<std::ptrdiff_t>(((z - z0) * dims[1] + y) * dims[0]);
            std::fill(slab.begin() + row + static_cast<std::ptrdiff_t>(x0),
                      slab.begin() + row + static_cast<std::ptrdiff_t>(x1), values[v]);
            if (keep_fine_only)
              std::fill(keep.begin() + row + static_cast<std::ptrdiff_t>(x0),
                        keep.begin() + row + static_cast<std::ptrdiff_t>(x1), fine ? 1 : 0);
          });
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
