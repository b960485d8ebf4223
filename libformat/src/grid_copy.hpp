// Reading a box of a regular or bricked grid (spec §8A.1, §8A.4) at full
// resolution by copying rows of decoded blocks straight into the output:
// the bricks of the box (as many layers of them as half the block cache
// holds) are fetched and decoded together (on several threads,
// fetch_plan.cpp), then each row is converted and copied in one loop,
// instead of looking every voxel up on its own. Internal to libformat.
#pragma once

#include <algorithm>
#include <cstdint>

#include "brick_grid.hpp"
#include "layout.hpp"
#include "reader_impl.hpp"

namespace ivol::detail {

// Whether copy_grid reads `box` of this file (else the caller walks it).
inline bool grid_copies(const Reader::Impl& impl, unsigned lod) {
  const StructureKind kind = impl.info.layout.kind;
  return lod == 0 && !impl.info.salvage && (kind == StructureKind::Regular || kind == StructureKind::Bricked);
}

// out[z][y][x] over `box` = convert(stored bits) for a grid_copies() file.
template <class T, class Convert>
void copy_grid(Reader::Impl& impl, const Box& box, T* out, Convert&& convert) {
  const VolumeLayout& v = impl.info.layout;
  const std::size_t width = encoding_width(v.encoding);
  const std::uint64_t nx = box.hi[0] - box.lo[0], ny = box.hi[1] - box.lo[1];
  auto row_out = [&](std::uint64_t y, std::uint64_t z) { return out + ((z - box.lo[2]) * ny + (y - box.lo[1])) * nx; };
  auto copy_run = [&](const std::uint8_t* src, T* dst, std::uint64_t count) {
    if (width == 2)
      for (std::uint64_t i = 0; i < count; ++i) dst[i] = convert(layout::load<std::uint16_t>(src + 2 * i));
    else
      for (std::uint64_t i = 0; i < count; ++i) dst[i] = convert(layout::load<std::uint32_t>(src + 4 * i));
  };
  if (v.kind == StructureKind::Regular) {
    impl.plan_box(box, 0);
    for (std::uint64_t z = box.lo[2]; z < box.hi[2]; ++z)
      for (std::uint64_t y = box.lo[1]; y < box.hi[1]; ++y) {
        std::uint64_t index = (z * v.dims[1] + y) * v.dims[0] + box.lo[0];
        T* dst = row_out(y, z);
        for (std::uint64_t left = nx; left > 0;) {
          std::uint64_t run = 0;
          const std::uint8_t* src = impl.elements(3, index, &run);
          run = std::min(run, left);
          copy_run(src, dst, run);
          dst += run, index += run, left -= run;
        }
      }
    return;
  }
  const unsigned b = v.cell_log2;
  const BrickGrid bricks(v.dims, b);
  // Layers of bricks planned together, as many as half the block cache
  // holds decoded: a y or x slice meets one layer after another, and one
  // plan of them all lets the byte source merge their ranges into a few
  // requests (a request a layer when each was planned alone), while a read
  // larger than the cache still goes a few layers at a time, each decoded
  // once.
  const std::uint32_t k_first = box.lo[2] >> b, k_last = (box.hi[2] - 1) >> b;
  const std::uint64_t bricks_a_layer =
      std::uint64_t{((box.hi[0] - 1) >> b) - (box.lo[0] >> b) + 1} * (((box.hi[1] - 1) >> b) - (box.lo[1] >> b) + 1);
  const std::uint64_t layer_bytes = bricks_a_layer * (std::uint64_t{width} << (3 * b));
  const std::uint64_t layers_a_plan = std::max<std::uint64_t>(1, impl.cache.capacity() / 2 / layer_bytes);
  for (std::uint32_t k = k_first; k <= k_last; ++k) {
    const std::uint64_t z0 = std::max<std::uint64_t>(box.lo[2], std::uint64_t{k} << b);
    const std::uint64_t z1 = std::min<std::uint64_t>(box.hi[2], (std::uint64_t{k} + 1) << b);
    if ((k - k_first) % layers_a_plan == 0) {
      const std::uint64_t plan_end = std::min<std::uint64_t>(box.hi[2], (std::uint64_t{k} + layers_a_plan) << b);
      impl.plan_box(Box{{box.lo[0], box.lo[1], static_cast<std::uint32_t>(z0)},
                        {box.hi[0], box.hi[1], static_cast<std::uint32_t>(plan_end)}},
                    0);
    }
    for (std::uint32_t j = box.lo[1] >> b; j <= (box.hi[1] - 1) >> b; ++j)
      for (std::uint32_t i = box.lo[0] >> b; i <= (box.hi[0] - 1) >> b; ++i) {
        const Dims e = bricks.extent(i, j, k);
        const std::uint64_t origin[3] = {std::uint64_t{i} << b, std::uint64_t{j} << b, std::uint64_t{k} << b};
        const std::uint64_t x0 = std::max<std::uint64_t>(box.lo[0], origin[0]);
        const std::uint64_t x1 = std::min<std::uint64_t>(box.hi[0], origin[0] + e[0]);
        const std::uint64_t y0 = std::max<std::uint64_t>(box.lo[1], origin[1]);
        const std::uint64_t y1 = std::min<std::uint64_t>(box.hi[1], origin[1] + e[1]);
        // A brick is one block (spec §8A.4); element() finds it, or throws
        // the error a walk would (a missing or damaged block).
        const std::uint64_t first = bricks.first_value(i, j, k);
        std::uint64_t available = 0;
        const std::uint8_t* brick = impl.elements(3, first, &available);
        const std::uint64_t voxels = std::uint64_t{e[0]} * e[1] * e[2];
        for (std::uint64_t z = z0; z < z1; ++z)
          for (std::uint64_t y = y0; y < y1; ++y) {
            const std::uint64_t at = ((z - origin[2]) * e[1] + (y - origin[1])) * e[0] + (x0 - origin[0]);
            if (available >= voxels) {
              copy_run(brick + at * width, row_out(y, z) + (x0 - box.lo[0]), x1 - x0);
              continue;
            }
            // A block that is not exactly this brick (a file whose blocks
            // split bricks): the row a run at a time.
            T* dst = row_out(y, z) + (x0 - box.lo[0]);
            for (std::uint64_t index = first + at, left = x1 - x0; left > 0;) {
              std::uint64_t run = 0;
              const std::uint8_t* src = impl.elements(3, index, &run);
              run = std::min(run, left);
              copy_run(src, dst, run);
              dst += run, index += run, left -= run;
            }
          }
      }
  }
}

}  // namespace ivol::detail
