// What every structure shares: bricks, values, dense conversions, lookup.
#include <algorithm>

#include "brick_rows.hpp"
#include "ivol/error.hpp"
#include "ivol/structures.hpp"

namespace ivol {

const char* structure_name(StructureKind kind) {
  switch (kind) {
    case StructureKind::Regular:
      return "regular";
    case StructureKind::Rectilinear:
      return "rectilinear";
    case StructureKind::Nested:
      return "nested";
    case StructureKind::Octree:
      return "octree";
    case StructureKind::Bricked:
      return "bricked";
  }
  return "unknown";
}

bool parse_structure(const std::string& name, StructureKind& out) {
  for (StructureKind k :
       {StructureKind::Regular, StructureKind::Rectilinear, StructureKind::Nested, StructureKind::Octree})
    if (name == structure_name(k)) {
      out = k;
      return true;
    }
  return false;
}

namespace {

constexpr std::uint32_t kTile = 16;  // lookup tiles of 16^3 full-resolution voxels

}  // namespace

void VoxelStructure::finish_bricks() { voxel_total_ = bricks_.assign_first_values(); }

std::vector<float>& VoxelStructure::values() {
  if (values_.size() != voxel_total_) values_.assign(voxel_total_, 0.0f);
  return values_;
}

const std::vector<float>& VoxelStructure::values() const {
  if (values_.size() != voxel_total_)
    throw Error(ErrorClass::InvalidArgument, "structure: no values yet (call values() or sample_dense first)");
  return values_;
}

void VoxelStructure::build_lookup() const {
  const Dims tiles{(dims_[0] + kTile - 1) / kTile, (dims_[1] + kTile - 1) / kTile, (dims_[2] + kTile - 1) / kTile};
  std::vector<std::uint32_t> counts(ivol::voxel_count(tiles) + 1, 0);
  auto for_tiles = [&](const Brick& b, auto&& visit) {
    std::uint32_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = b.origin[a] / kTile;
      hi[a] = (std::min<std::uint64_t>(dims_[a], b.origin[a] + std::uint64_t{b.voxel[a]} * b.count[a]) - 1) / kTile;
    }
    for (std::uint32_t k = lo[2]; k <= hi[2]; ++k)
      for (std::uint32_t j = lo[1]; j <= hi[1]; ++j)
        for (std::uint32_t i = lo[0]; i <= hi[0]; ++i) visit((std::uint64_t{k} * tiles[1] + j) * tiles[0] + i);
  };
  for (const Brick& b : bricks_) for_tiles(b, [&](std::uint64_t t) { ++counts[t + 1]; });
  for (std::size_t t = 1; t < counts.size(); ++t) counts[t] += counts[t - 1];
  tile_start_ = counts;
  owner_.assign(counts.back(), 0);
  std::vector<std::uint32_t> fill(counts.begin(), counts.end() - 1);
  for (std::uint32_t n = 0; n < bricks_.size(); ++n)
    for_tiles(bricks_[n], [&](std::uint64_t t) { owner_[fill[t]++] = n; });
}

std::uint64_t VoxelStructure::value_index(std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
  if (x >= dims_[0] || y >= dims_[1] || z >= dims_[2])
    throw Error(ErrorClass::InvalidArgument, "value_index: voxel outside the volume");
  if (tile_start_.empty()) build_lookup();
  const Dims tiles{(dims_[0] + kTile - 1) / kTile, (dims_[1] + kTile - 1) / kTile, (dims_[2] + kTile - 1) / kTile};
  const std::uint64_t t = (std::uint64_t{z / kTile} * tiles[1] + y / kTile) * tiles[0] + x / kTile;
  const std::uint32_t p[3] = {x, y, z};
  for (std::uint32_t e = tile_start_[t]; e < tile_start_[t + 1]; ++e) {
    const Brick& b = bricks_[owner_[e]];
    std::uint64_t local[3];
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      if (p[a] < b.origin[a])
        inside = false;
      else {
        local[a] = (p[a] - b.origin[a]) / b.voxel[a];
        inside = local[a] < b.count[a];
      }
    }
    if (inside) return b.first_value + (local[2] * b.count[1] + local[1]) * b.count[0] + local[0];
  }
  throw Error(ErrorClass::Malformed, "value_index: no brick covers the voxel");
}

void VoxelStructure::to_dense(float* out) const {
  const std::vector<float>& vals = values();
  for (const Brick& b : bricks_)
    detail::for_each_brick_row(
        b, dims_, 0, dims_[2],
        [&](std::uint64_t v, std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint64_t z) {
          std::fill(out + (z * dims_[1] + y) * dims_[0] + x0, out + (z * dims_[1] + y) * dims_[0] + x1, vals[v]);
        });
}

void VoxelStructure::sample_dense(const float* dense) {
  std::vector<float>& vals = values();
  std::vector<double> sum(vals.size(), 0.0);
  std::vector<std::uint64_t> count(vals.size(), 0);
  for (const Brick& b : bricks_)
    detail::for_each_brick_row(
        b, dims_, 0, dims_[2],
        [&](std::uint64_t v, std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint64_t z) {
          const float* row = dense + (z * dims_[1] + y) * dims_[0];
          for (std::uint64_t x = x0; x < x1; ++x) sum[v] += row[x];
          count[v] += x1 - x0;
        });
  for (std::size_t v = 0; v < vals.size(); ++v)
    vals[v] = count[v] ? static_cast<float>(sum[v] / static_cast<double>(count[v])) : 0.0f;
}

}  // namespace ivol
