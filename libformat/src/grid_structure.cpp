#include "grid_structure.hpp"

#include "ivol/error.hpp"

namespace ivol::detail {

GridStructure::GridStructure(const VolumeLayout& layout, std::vector<std::uint32_t> borders,
                             std::vector<std::uint64_t> cells, std::uint64_t values_in_file, const std::string& where)
    : layout_(layout), cells_(std::move(cells)) {
  auto fail = [&](const std::string& part, const std::string& what) {
    throw Error(ErrorClass::Malformed, where + ": " + part + ": " + what);
  };
  const Dims& d = layout.dims;
  std::uint64_t total = 0;
  switch (layout.kind) {
    case StructureKind::Regular:
    case StructureKind::Bricked:
      // One value per voxel: past 2^56 no file holds them (the limit of
      // the other kinds); checked before voxel_count, which throws past 2^64.
      if (voxel_count_approx(d) > static_cast<double>(std::uint64_t{1} << 56))
        fail("values", "a regular grid of " + std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" +
                           std::to_string(d[2]) + " voxels has more than 2^56 values");
      total = voxel_count(d);
      break;
    case StructureKind::Rectilinear: {
      // Three lists, each from 0 strictly up to the size along its axis.
      std::size_t at = 0;
      total = 1;
      for (int a = 0; a < 3; ++a) {
        const std::string axis = std::string("borders along ") + "xyz"[a];
        if (at >= borders.size() || borders[at] != 0) fail(axis, "the list does not start with 0");
        std::vector<std::uint32_t>& list = borders_[a];
        list.push_back(0);
        ++at;
        while (true) {
          if (at >= borders.size()) fail(axis, "the list does not end with " + std::to_string(d[a]));
          const std::uint32_t b = borders[at++];
          if (b <= list.back())
            fail(axis,
                 "positions do not increase (" + std::to_string(b) + " after " + std::to_string(list.back()) + ")");
          if (b > d[a]) fail(axis, "position " + std::to_string(b) + " exceeds the size " + std::to_string(d[a]));
          list.push_back(b);
          if (b == d[a]) break;
        }
        const std::uint64_t n = list.size() - 1;
        if (total > (std::uint64_t{1} << 56) / n) fail("borders", "more than 2^56 cells");
        total *= n;
      }
      if (at != borders.size()) fail("borders", std::to_string(borders.size() - at) + " elements after the z list");
      break;
    }
    case StructureKind::Nested: {
      cell_edge_ = std::uint64_t{1} << layout.cell_log2;
      for (int a = 0; a < 3; ++a) cell_grid_[a] = static_cast<std::uint32_t>((d[a] + cell_edge_ - 1) / cell_edge_);
      std::uint64_t n = 0;
      for (std::uint32_t k = 0; k < cell_grid_[2]; ++k)
        for (std::uint32_t j = 0; j < cell_grid_[1]; ++j)
          for (std::uint32_t i = 0; i < cell_grid_[0]; ++i, ++n) {
            const std::uint64_t word = cells_[n];
            const unsigned e = static_cast<unsigned>(word >> 56);
            const std::uint64_t first = word & ((std::uint64_t{1} << 56) - 1);
            const std::string cell = "cell " + std::to_string(n);
            if (e > layout.cell_log2)
              fail(cell, "exponent " + std::to_string(e) + " exceeds cell_log2 " + std::to_string(layout.cell_log2));
            if (first != total)
              fail(cell,
                   "first_value is " + std::to_string(first) + ", the cells before it hold " + std::to_string(total));
            const std::uint64_t h = cell_edge_ >> e;
            const std::uint32_t c[3] = {i, j, k};
            // Counts up to 2^31 per axis: bound the product at 2^56 as it grows.
            constexpr std::uint64_t kMaxValues = std::uint64_t{1} << 56;
            std::uint64_t count = 1;
            for (int a = 0; a < 3; ++a) {
              const std::uint64_t ext = std::min<std::uint64_t>(cell_edge_, d[a] - std::uint64_t{c[a]} * cell_edge_);
              const std::uint64_t m = (ext + h - 1) / h;
              if (count > kMaxValues / m) fail(cell, "holds more than 2^56 values");
              count *= m;
            }
            if (total + count > kMaxValues) fail(cell, "the values of the cells exceed 2^56");
            total += count;
          }
      break;
    }
    case StructureKind::Octree:
      break;
  }
  if (values_in_file != kValuesUnknown && total != values_in_file)
    fail("values", "the file holds " + std::to_string(values_in_file) + " values, the structure has " +
                       std::to_string(total) + " cells");
}

}  // namespace ivol::detail
