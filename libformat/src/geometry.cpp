#include "ivol/geometry.hpp"

#include <algorithm>
#include <sstream>

#include "ivol/error.hpp"

namespace ivol {

std::uint64_t Box::voxel_count() const {
  if (empty()) return 0;
  return ivol::voxel_count(Dims{hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
}

bool Box::empty() const { return hi[0] <= lo[0] || hi[1] <= lo[1] || hi[2] <= lo[2]; }

std::string Box::to_string() const {
  std::ostringstream s;
  s << "[" << lo[0] << "," << lo[1] << "," << lo[2] << " .. " << hi[0] << "," << hi[1] << "," << hi[2] << ")";
  return s.str();
}

unsigned depth_for(const Dims& dims) {
  const std::uint64_t largest = std::max({dims[0], dims[1], dims[2]});
  unsigned depth = 0;
  while ((std::uint64_t{1} << depth) < largest) ++depth;
  return depth;
}

std::uint64_t voxel_count(const Dims& dims) {
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];  // at most 2^64 - 2^33 + 1
  std::uint64_t voxels = 0;
  if (__builtin_mul_overflow(slice, std::uint64_t{dims[2]}, &voxels))
    throw Error(ErrorClass::LimitExceeded, std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                               std::to_string(dims[2]) + " voxels: more than 2^64 - 1");
  return voxels;
}

double voxel_count_approx(const Dims& dims) {
  return static_cast<double>(dims[0]) * static_cast<double>(dims[1]) * static_cast<double>(dims[2]);
}

Dims lod_dims(const Dims& dims, unsigned lod) {
  Dims out{};
  for (int a = 0; a < 3; ++a) {
    const std::uint64_t side = std::uint64_t{1} << lod;
    out[a] = static_cast<std::uint32_t>((dims[a] + side - 1) / side);
  }
  return out;
}

Box full_box(const Dims& dims, unsigned lod) {
  const Dims d = lod_dims(dims, lod);
  return Box{{0, 0, 0}, {d[0], d[1], d[2]}};
}

Box slice_box(const Dims& dims, Axis axis, std::uint32_t index) {
  Box box = full_box(dims);
  const int a = static_cast<int>(axis);
  box.lo[a] = index;
  box.hi[a] = index + 1;
  return box;
}

std::uint64_t VolumeLayout::total_inner() const {
  std::uint64_t total = 0;
  for (auto c : inner_count) total += c;
  return total;
}

std::uint64_t VolumeLayout::first_inner(unsigned level) const {
  std::uint64_t first = 0;
  for (unsigned l = 0; l < level && l < inner_count.size(); ++l) first += inner_count[l];
  return first;
}

std::uint64_t VolumeLayout::first_value(unsigned level) const {
  return level == 0 ? 0 : 1 + 8 * first_inner(level - 1);
}

std::uint64_t VolumeLayout::level_values(unsigned level) const { return level == 0 ? 1 : 8 * inner_count[level - 1]; }

double VolumeLayout::weight_f64(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
  // The exact product (up to 2^93) rounded once to binary64, as spec §10 says.
  const std::uint64_t side = std::uint64_t{1} << (depth - level);
  __extension__ using Wide = unsigned __int128;
  auto overlap = [side](std::uint64_t a, std::uint64_t n) -> Wide {
    const std::uint64_t lo = a * side;
    const std::uint64_t hi = std::min(n, lo + side);
    return hi > lo ? hi - lo : 0;
  };
  return static_cast<double>(overlap(i, dims[0]) * overlap(j, dims[1]) * overlap(k, dims[2]));
}

}  // namespace ivol
