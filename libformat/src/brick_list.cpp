// Packing and unpacking the 16-byte brick records (ivol/brick_list.hpp).
#include "ivol/brick_list.hpp"

#include <algorithm>
#include <numeric>
#include <string>

#include "ivol/error.hpp"

namespace ivol {

namespace {

constexpr std::uint64_t kAxisMask = (std::uint64_t{1} << BrickList::kAxisBits) - 1;
constexpr std::uint64_t kFirstValueMask = (std::uint64_t{1} << BrickList::kFirstValueBits) - 1;
constexpr std::uint32_t kMaxShapeCode = (1U << (64 - BrickList::kFirstValueBits)) - 1;

unsigned ceil_log2(std::uint32_t v) {
  unsigned l = 0;
  while ((std::uint64_t{1} << l) < v) ++l;
  return l;
}

}  // namespace

BrickList::BrickList(const Dims& dims) : dims_(dims) {
  for (int a = 0; a < 3; ++a)
    if (dims[a] > (std::uint64_t{1} << kAxisBits))
      throw Error(ErrorClass::LimitExceeded, "structure: " + std::to_string(dims[a]) +
                                                 " voxels along an axis; bricks reach at most 2^21 (2,097,152)");
}

std::uint64_t BrickList::pack_origin(const std::array<std::uint32_t, 3>& o) {
  return std::uint64_t{o[0]} | (std::uint64_t{o[1]} << kAxisBits) | (std::uint64_t{o[2]} << (2 * kAxisBits));
}

Brick BrickList::decode(const PackedBrick& r) const {
  Brick b;
  for (int a = 0; a < 3; ++a) b.origin[a] = static_cast<std::uint32_t>((r.origin >> (a * kAxisBits)) & kAxisMask);
  b.first_value = r.value & kFirstValueMask;
  const auto code = static_cast<std::uint32_t>(r.value >> kFirstValueBits);
  if (code >= kCubeCodes) {
    const Shape& s = shapes_[code - kCubeCodes];
    b.voxel = s.voxel;
    b.count = s.count;
    return b;
  }
  const std::uint32_t side = 1U << (code >> 1);
  std::array<std::uint32_t, 3> extent{};
  for (int a = 0; a < 3; ++a) extent[a] = std::min(side, dims_[a] - b.origin[a]);
  const std::array<std::uint32_t, 3> one{1, 1, 1};
  const bool fine = (code & 1U) != 0;
  b.voxel = fine ? one : extent;
  b.count = fine ? extent : one;
  return b;
}

std::optional<PackedBrick> BrickList::cube_record(const Brick& b) const {
  const std::array<std::uint32_t, 3> one{1, 1, 1};
  const bool fine = b.voxel == one;
  if (!fine && b.count != one) return std::nullopt;
  const std::array<std::uint32_t, 3>& extent = fine ? b.count : b.voxel;
  for (int a = 0; a < 3; ++a)
    if (b.origin[a] >= dims_[a] || extent[a] == 0) return std::nullopt;
  // The smallest side that clips to this extent, if any does: a clipped
  // side's extent is what is left of the volume, a whole one's the side.
  const std::uint32_t side = 1U << ceil_log2(std::max({extent[0], extent[1], extent[2]}));
  for (int a = 0; a < 3; ++a)
    if (extent[a] != std::min(side, dims_[a] - b.origin[a])) return std::nullopt;
  const std::uint64_t code = ceil_log2(side) * 2U + (fine ? 1U : 0U);
  return PackedBrick{pack_origin(b.origin), code << kFirstValueBits};
}

std::uint32_t BrickList::shape_code(const Brick& b) {
  const std::array<std::uint32_t, 6> key{b.voxel[0], b.voxel[1], b.voxel[2], b.count[0], b.count[1], b.count[2]};
  const auto found = shape_codes_.find(key);
  if (found != shape_codes_.end()) return found->second;
  const auto code = static_cast<std::uint32_t>(kCubeCodes + shapes_.size());
  if (code > kMaxShapeCode) throw Error(ErrorClass::LimitExceeded, "structure: more than 2^24 brick shapes");
  shapes_.push_back(Shape{b.voxel, b.count});
  shape_codes_.emplace(key, code);
  return code;
}

void BrickList::push_back(const Brick& b) {
  for (int a = 0; a < 3; ++a)
    if (b.origin[a] >= dims_[a]) throw Error(ErrorClass::InvalidArgument, "structure: a brick outside the volume");
  if (const std::optional<PackedBrick> cube = cube_record(b)) {
    records_.push_back(*cube);
    return;
  }
  records_.push_back(PackedBrick{pack_origin(b.origin), std::uint64_t{shape_code(b)} << kFirstValueBits});
}

void BrickList::append(const std::vector<PackedBrick>& records) {
  records_.insert(records_.end(), records.begin(), records.end());
}

void BrickList::sort_by_first_slice() {
  std::vector<std::uint32_t> order(records_.size());
  std::iota(order.begin(), order.end(), 0U);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return records_[a].z() < records_[b].z(); });
  // Position n takes record order[n]: follow each cycle once, marking the
  // positions done by setting order[n] = n.
  for (std::uint32_t n = 0; n < order.size(); ++n) {
    if (order[n] == n) continue;
    const PackedBrick first = records_[n];
    std::uint32_t at = n;
    while (order[at] != n) {
      const std::uint32_t from = order[at];
      records_[at] = records_[from];
      order[at] = at;
      at = from;
    }
    records_[at] = first;
    order[at] = at;
  }
}

std::uint64_t BrickList::assign_first_values() {
  std::uint64_t next = 0;
  for (PackedBrick& r : records_) {
    if (next > kFirstValueMask) throw Error(ErrorClass::LimitExceeded, "structure: more than 2^40 values");
    r.value = (r.value & ~kFirstValueMask) | next;
    next += decode(r).voxel_count();
  }
  return next;
}

std::uint64_t BrickList::memory_bytes() const {
  return records_.capacity() * sizeof(PackedBrick) + shapes_.capacity() * sizeof(Shape) +
         shape_codes_.size() * (sizeof(std::array<std::uint32_t, 6>) + 48);
}

}  // namespace ivol
