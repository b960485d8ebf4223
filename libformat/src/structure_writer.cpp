// Any structure into an .ivol octree file, one slab of slices at a time.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "block_pipeline.hpp"
#include "brick_rows.hpp"
#include "ivol/error.hpp"
#include "ivol/structures.hpp"

namespace ivol {

namespace {

// The regular, rectilinear and nested grids in their own form (spec §8A):
// borders or cell words, then the values in the grid's order.
StreamingResult write_grid(const VoxelStructure& structure, const std::string& path, const Metadata& metadata,
                           const StreamingOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const BuildOptions& build = options.build;
  VolumeLayout layout;
  layout.kind = structure.kind();
  layout.dims = structure.dims();
  layout.depth = depth_for(layout.dims);
  layout.encoding = build.encoding;
  layout.value_scale = build.value_scale;
  layout.value_offset = build.value_offset;
  layout.inner_count.assign(layout.depth + 1, 0);
  unsigned cell_log2 = 0;
  while ((1u << cell_log2) < structure.nested_cell()) ++cell_log2;
  layout.cell_log2 = static_cast<std::uint8_t>(layout.kind == StructureKind::Nested ? cell_log2 : 0);

  FileWriter writer(path, layout);
  detail::BlockPipeline pipeline(writer, options.write);
  const std::uint32_t block = options.write.block_bytes;
  const auto& bricks = structure.bricks();
  if (layout.kind == StructureKind::Rectilinear) {
    detail::BlockAssembler borders(pipeline, Stream::Borders, 0, 0, 4, block);
    for (const auto& list : structure.borders()) borders.append(list.data(), list.size());
    borders.finish();
  }
  if (layout.kind == StructureKind::Nested) {
    detail::BlockAssembler cells(pipeline, Stream::Cells, 0, 0, 8, block);
    for (const Brick& b : bricks) {
      const bool fine = b.voxel == std::array<std::uint32_t, 3>{1, 1, 1};
      const std::uint64_t word = make_node_word(static_cast<std::uint8_t>(fine ? cell_log2 : 0), b.first_value);
      cells.append(&word, 1);
    }
    cells.finish();
  }

  // Values in the grid's order: the bricks' order for the regular and nested
  // grids; (k, j, i) over the intervals for the rectilinear grid.
  const std::vector<float>& values = structure.values();
  std::vector<std::uint64_t> order;
  if (layout.kind == StructureKind::Rectilinear) {
    const auto& borders = structure.borders();
    const std::uint64_t nx = borders[0].size() - 1, ny = borders[1].size() - 1;
    auto interval = [&](int a, std::uint32_t position) {
      return static_cast<std::uint64_t>(std::lower_bound(borders[a].begin(), borders[a].end(), position) -
                                        borders[a].begin());
    };
    order.resize(values.size());
    for (const Brick& b : bricks) {
      const std::uint64_t i0 = interval(0, b.origin[0]), j0 = interval(1, b.origin[1]), k0 = interval(2, b.origin[2]);
      for (std::uint32_t k = 0; k < b.count[2]; ++k)
        for (std::uint32_t j = 0; j < b.count[1]; ++j)
          for (std::uint32_t i = 0; i < b.count[0]; ++i)
            order[((k0 + k) * ny + (j0 + j)) * nx + (i0 + i)] =
                b.first_value + (std::uint64_t{k} * b.count[1] + j) * b.count[0] + i;
    }
  }
  const std::size_t width = encoding_width(build.encoding);
  const bool identity = build.value_scale == 1.0 && build.value_offset == 0.0;
  StreamingResult result;
  detail::BlockAssembler out(pipeline, Stream::Values, 0, 0, width, block);
  for (std::uint64_t n = 0; n < values.size(); ++n) {
    const float v = values[order.empty() ? n : order[n]];
    const double stored = identity ? v : (v - build.value_offset) / build.value_scale;
    const std::uint32_t bits = encode_value(build.encoding, stored);
    const double err = std::fabs(layout.physical(decode_value(build.encoding, bits)) - v);
    if (err > result.max_abs_error) result.max_abs_error = err;
    out.append(&bits, 1);  // little-endian: the low bytes are the value
  }
  out.finish();
  pipeline.flush();
  writer.finish(metadata, layout.inner_count);
  result.lossless = result.max_abs_error == 0.0;
  result.kept_voxels = values.size();
  result.write.file_bytes = writer.bytes_written();
  result.write.block_count = writer.block_count();
  result.write.decoded_bytes = pipeline.decoded_bytes();
  result.write.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace

StreamingResult write_structure(const VoxelStructure& structure, const std::string& path, const Metadata& metadata,
                                StreamingOptions options) {
  if (structure.kind() != StructureKind::Octree) return write_grid(structure, path, metadata, options);
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
