#include "ivol/octree.hpp"

#include <cstring>

#include "box_output.hpp"
#include "ivol/error.hpp"
#include "tree_verify.hpp"
#include "tree_walk.hpp"

namespace ivol {
namespace {

struct MemoryAccess {
  const Octree& tree;
  std::uint64_t node_word(std::uint64_t i) const { return tree.node_word(i); }
  std::uint32_t value_bits(std::uint64_t i) const { return tree.value_bits(i); }
  // The walk's runs: none (the lookups above are as cheap in memory).
  const std::uint8_t* run(std::uint8_t, std::uint64_t, std::uint64_t) const { return nullptr; }
  std::size_t value_width() const { return encoding_width(tree.layout().encoding); }
  void values8(std::uint64_t i, std::uint32_t* bits) const {
    for (unsigned c = 0; c < 8; ++c) bits[c] = tree.value_bits(i + c);
  }
  const Error* known_failure(std::uint8_t, std::uint64_t) const { return nullptr; }  // nothing fails in memory
};

}  // namespace

Octree::Octree(VolumeLayout layout, std::vector<std::uint64_t> nodes, std::vector<std::uint8_t> values)
    : layout_(std::move(layout)), nodes_(std::move(nodes)), values_(std::move(values)) {
  if (layout_.inner_count.size() != layout_.depth + 1 || nodes_.size() != layout_.total_inner() ||
      values_.size() != layout_.total_values() * encoding_width(layout_.encoding))
    throw Error(ErrorClass::InvalidArgument, "Octree: array sizes do not match the level table");
}

std::uint32_t Octree::value_bits(std::uint64_t index) const {
  const std::size_t width = encoding_width(layout_.encoding);
  if (width == 2) {
    std::uint16_t v;
    std::memcpy(&v, values_.data() + index * 2, 2);
    return v;
  }
  std::uint32_t v;
  std::memcpy(&v, values_.data() + index * 4, 4);
  return v;
}

std::uint32_t Octree::voxel_bits(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod) const {
  MemoryAccess access{*this};
  const detail::LevelRanges ranges(layout_);
  return detail::lookup_bits(access, layout_, ranges, x, y, z, lod);
}

double Octree::voxel_value(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod) const {
  return layout_.physical(decode_value(layout_.encoding, voxel_bits(x, y, z, lod)));
}

std::vector<float> Octree::read_box(const Box& box, unsigned lod) const {
  std::vector<float> out(box.voxel_count());
  MemoryAccess access{*this};
  const detail::LevelRanges ranges(layout_);
  detail::walk_box(access, layout_, ranges, box, lod, detail::box_output(out.data(), box, [this](std::uint32_t bits) {
                     return static_cast<float>(layout_.physical(decode_value(layout_.encoding, bits)));
                   }));
  return out;
}

MemoryUsage Octree::memory() const { return MemoryUsage{nodes_.size() * sizeof(std::uint64_t), values_.size()}; }

std::uint64_t Octree::leaf_count() const { return layout_.total_values() - layout_.total_inner(); }

void Octree::validate() const {
  MemoryAccess access{*this};
  detail::TreeVerifier<MemoryAccess> verifier(access, layout_);
  verifier.run();
}

}  // namespace ivol
