// Full verification of an octree against spec §8 and §10: breadth-first
// numbering, child masks, padding, and every inner average bit for bit.
// Shared by Octree::validate and check_file.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "ivol/encoding.hpp"
#include "tree_walk.hpp"

namespace ivol::detail {

inline std::string hex_bits(std::uint32_t bits) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%X", bits);
  return text;
}

template <class Access>
class TreeVerifier {
 public:
  TreeVerifier(Access& access, const VolumeLayout& layout) : access_(access), layout_(layout), ranges_(layout) {
    next_child_.resize(layout.depth + 1);
    for (unsigned l = 0; l <= layout.depth; ++l) next_child_[l] = ranges_.first_inner[l + 1];
  }

  void run() {
    if (layout_.inner_count.size() != layout_.depth + 1)
      throw Error(ErrorClass::Malformed, "level table has the wrong number of levels");
    visit(0, 0, 0, 0, 0, layout_.inner_count[0] ? 0 : kNoInner);
    for (unsigned l = 0; l < layout_.depth; ++l) {
      if (next_child_[l] != ranges_.first_inner[l + 2])
        throw Error(ErrorClass::Malformed, "level table: inner_count[" + std::to_string(l + 1) + "] is " +
                                               std::to_string(layout_.inner_count[l + 1]) +
                                               " but the child masks of level " + std::to_string(l) + " name " +
                                               std::to_string(next_child_[l] - ranges_.first_inner[l + 1]));
    }
  }

 private:
  double visit(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, std::uint64_t value_index,
               std::uint64_t inner) {
    const double w = layout_.weight_f64(level, i, j, k);
    const std::uint32_t bits = access_.value_bits(value_index);
    auto where = [&] {
      return "node at level " + std::to_string(level) + " (" + std::to_string(i) + "," + std::to_string(j) + "," +
             std::to_string(k) + "), value " + std::to_string(value_index);
    };
    if (w == 0) {
      if (inner != kNoInner)
        throw Error(ErrorClass::Malformed, where() + ": a node entirely in the padding is subdivided");
      if (bits != 0)
        throw Error(ErrorClass::Malformed, where() + ": a padding leaf's value is " + hex_bits(bits) + ", not zero");
      return 0.0;
    }
    if (inner == kNoInner) return decode_value(layout_.encoding, bits);

    const std::uint64_t word = access_.node_word(inner);
    check_node_word(layout_, ranges_, level, inner, word);
    const unsigned mask = child_mask(word);
    const std::uint64_t first = first_inner_child(word);
    if (first != next_child_[level])
      throw Error(ErrorClass::Malformed, "node " + std::to_string(inner) + " (level " + std::to_string(level) +
                                             "): first_inner_child is " + std::to_string(first) +
                                             ", breadth-first order requires " + std::to_string(next_child_[level]));
    next_child_[level] += popcount8(mask);

    double acc = 0.0;
    double total_weight = 0.0;
    for (unsigned c = 0; c < 8; ++c) {
      const std::uint32_t ci = 2 * i + (c & 1u);
      const std::uint32_t cj = 2 * j + ((c >> 1) & 1u);
      const std::uint32_t ck = 2 * k + ((c >> 2) & 1u);
      const std::uint64_t child_inner = (mask >> c) & 1u ? first + popcount8(mask & ((1u << c) - 1u)) : kNoInner;
      const double m = visit(level + 1, ci, cj, ck, 1 + 8 * inner + c, child_inner);
      const double wc = layout_.weight_f64(level + 1, ci, cj, ck);
      if (wc > 0) {
        acc = acc + wc * m;
        total_weight = total_weight + wc;
      }
    }
    const double mean = acc / total_weight;
    const std::uint32_t expected = encode_value(layout_.encoding, mean);
    if (expected != bits)
      throw Error(ErrorClass::Malformed, where() + ": stored average " + hex_bits(bits) +
                                             " differs from the mean of its voxels " + hex_bits(expected) +
                                             " (spec §10)");
    return mean;
  }

  Access& access_;
  const VolumeLayout& layout_;
  LevelRanges ranges_;
  std::vector<std::uint64_t> next_child_;
};

}  // namespace ivol::detail
