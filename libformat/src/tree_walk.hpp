// Descending the pointer-packed octree (spec §8.3), shared by the in-memory
// Octree and the file Reader. `Access` provides node_word(i) and value_bits(i).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "ivol/error.hpp"
#include "ivol/geometry.hpp"
#include "ivol/octree.hpp"
#include "ivol/reader.hpp"
#include "layout.hpp"
#include "salvage_log.hpp"

namespace ivol::detail {

constexpr std::uint64_t kNoInner = ~std::uint64_t{0};

// Per-level index ranges, precomputed once per file.
struct LevelRanges {
  std::vector<std::uint64_t> first_inner;  // depth + 2 entries; [l, l+1) is level l
  explicit LevelRanges(const VolumeLayout& layout) {
    first_inner.resize(layout.depth + 2, 0);
    for (unsigned l = 0; l <= layout.depth; ++l) first_inner[l + 1] = first_inner[l] + layout.inner_count[l];
  }
};

// Without -mpopcnt, __builtin_popcount is a call into libgcc: on a walk
// that meets every node, a measurable share of the read.
inline unsigned popcount8(unsigned v) {
  v &= 0xFFu;
  v = v - ((v >> 1) & 0x55u);
  v = (v & 0x33u) + ((v >> 2) & 0x33u);
  return (v + (v >> 4)) & 0x0Fu;
}

// A sink with octet(x, y, z, bits): takes the eight voxels of a 2x2x2 cube
// at (x, y, z) that lies wholly inside the box, bits(c) for child c (spec
// §8.3: c = dx | dy << 1 | dz << 2), in one call.
template <class Sink, class = void>
struct TakesOctets : std::false_type {};
template <class Sink>
struct TakesOctets<
    Sink, std::void_t<decltype(std::declval<Sink&>().octet(0u, 0u, 0u, std::declval<std::uint32_t (*)(unsigned)>()))>>
    : std::true_type {};

// A sink with cube(x, y, z, values): takes a 4^3 cube's 64 stored values
// (its eight children's, in child order) at once, where it can.
template <class Sink, class = void>
struct TakesCubes : std::false_type {};
template <class Sink>
struct TakesCubes<Sink, std::void_t<decltype(std::declval<const Sink&>().cube(
                            0u, 0u, 0u, static_cast<const std::uint8_t*>(nullptr)))>> : std::true_type {};

// Hands a 2x2x2 cube to the sink, bits(c) for child c: in one call where
// the sink takes octets, else voxel by voxel.
template <class Sink, class Bits>
void put_octet(Sink& sink, std::uint32_t x, std::uint32_t y, std::uint32_t z, Bits bits) {
  if constexpr (TakesOctets<Sink>::value) {
    sink.octet(x, y, z, bits);
  } else {
    for (unsigned c = 0; c < 8; ++c) {
      const std::uint32_t at[3] = {x + (c & 1u), y + ((c >> 1) & 1u), z + ((c >> 2) & 1u)};
      sink(Box{{at[0], at[1], at[2]}, {at[0] + 1, at[1] + 1, at[2] + 1}}, bits(c));
    }
  }
}

// Why a node word breaks the rules of check_node_word: out of line, so that
// the check itself, met for every node a read visits, stays small enough to
// inline.
[[gnu::noinline, gnu::cold]] inline void fail_node_word(const VolumeLayout& layout, const LevelRanges& ranges,
                                                        unsigned level, std::uint64_t index, std::uint64_t word) {
  const unsigned mask = child_mask(word);
  const std::uint64_t first = first_inner_child(word);
  auto fail = [&](const std::string& what) {
    throw Error(ErrorClass::Malformed,
                "node " + std::to_string(index) + " (level " + std::to_string(level) + "): " + what);
  };
  if (level + 1 > layout.depth) fail("an inner node at the deepest level");
  if (level + 1 == layout.depth && mask != 0)
    fail("child_mask is not 0 at level D-1, whose children are single voxels");
  const std::uint64_t lo = ranges.first_inner[level + 1];
  const std::uint64_t hi = ranges.first_inner[level + 2];
  fail("first_inner_child " + std::to_string(first) + " with " + std::to_string(popcount8(mask)) +
       " inner children lies outside level " + std::to_string(level + 1) + "'s nodes [" + std::to_string(lo) + ", " +
       std::to_string(hi) + ")");
}

// Rules a reader checks for every inner node it visits (§8.3, §8.4).
inline void check_node_word(const VolumeLayout& layout, const LevelRanges& ranges, unsigned level, std::uint64_t index,
                            std::uint64_t word) {
  const unsigned mask = child_mask(word);
  const std::uint64_t first = first_inner_child(word);
  if (level + 1 > layout.depth || (level + 1 == layout.depth && mask != 0) || first < ranges.first_inner[level + 1] ||
      first > ranges.first_inner[level + 2] || first + popcount8(mask) > ranges.first_inner[level + 2])
    fail_node_word(layout, ranges, level, index, word);
}

template <class Access>
std::uint32_t lookup_bits(Access& access, const VolumeLayout& layout, const LevelRanges& ranges, std::uint32_t x,
                          std::uint32_t y, std::uint32_t z, unsigned lod) {
  const unsigned target = layout.depth - lod;
  std::uint64_t value_index = 0;
  std::uint64_t inner = layout.inner_count[0] ? 0 : kNoInner;
  for (unsigned level = 0; level < target && inner != kNoInner; ++level) {
    const std::uint64_t word = access.node_word(inner);
    check_node_word(layout, ranges, level, inner, word);
    const unsigned shift = target - level - 1;
    const unsigned c = ((x >> shift) & 1u) | (((y >> shift) & 1u) << 1) | (((z >> shift) & 1u) << 2);
    const unsigned mask = child_mask(word);
    value_index = 1 + 8 * inner + c;
    inner = (mask >> c) & 1u ? first_inner_child(word) + popcount8(mask & ((1u << c) - 1u)) : kNoInner;
  }
  return access.value_bits(value_index);
}

[[gnu::noinline, gnu::cold]] inline void fail_order(unsigned level, std::uint64_t index, std::uint64_t first,
                                                    std::uint64_t required, bool exact) {
  throw Error(ErrorClass::Malformed, "node " + std::to_string(index) + " (level " + std::to_string(level) +
                                         "): first_inner_child is " + std::to_string(first) +
                                         ", breadth-first order requires " + (exact ? "" : "at least ") +
                                         std::to_string(required));
}


// The running counts of the node numbering (spec §8.3, §8.4) for the levels
// a walk descends: in octant order, the nodes of a level come in
// breadth-first order, so each node's children follow those of the node of
// its level met before it (a DAG, nodes sharing children, breaks this), and
// a read of a whole level meets every node: each first_inner_child is then
// exactly the running count (`exact`), and the counts add up to the level
// table's. A walk of one subtree (a parallel whole read) starts with the
// counts unknown: it records the first node it meets at each level, and the
// caller chains the subtrees' counts in order.
class NodeNumbering {
 public:
  static constexpr std::uint64_t kUnknown = ~std::uint64_t{0};

  NodeNumbering(const LevelRanges& ranges, unsigned target, bool exact)
      : exact(exact), next_child(target), first_node(target, kUnknown), first_child(target, kUnknown) {
    for (unsigned l = 0; l < target; ++l) next_child[l] = ranges.first_inner[l + 1];
  }

  // Counts unknown from `level` down, for a walk of a subtree rooted there.
  void start_subtree(unsigned level) {
    for (std::size_t l = level; l < next_child.size(); ++l) next_child[l] = first_node[l] = first_child[l] = kUnknown;
  }

  // Inlined: met at every node a walk visits.
  [[gnu::always_inline]] void check(unsigned level, std::uint64_t index, std::uint64_t word) {
    const std::uint64_t first = first_inner_child(word);
    std::uint64_t& next = next_child[level];
    if (next == kUnknown) {
      first_node[level] = index;
      first_child[level] = first;
    } else if (exact ? first != next : first < next) {
      fail_order(level, index, first, next, exact);
    }
    next = first + popcount8(child_mask(word));
  }

  // The level table's counts against those the walk met (a whole level).
  void check_totals(const VolumeLayout& layout, const LevelRanges& ranges) const {
    for (unsigned l = 0; l < next_child.size(); ++l)
      if (next_child[l] != ranges.first_inner[l + 2])
        throw Error(ErrorClass::Malformed, "level table: inner_count[" + std::to_string(l + 1) + "] is " +
                                               std::to_string(layout.inner_count[l + 1]) +
                                               " but the child masks of level " + std::to_string(l) + " name " +
                                               std::to_string(next_child[l] - ranges.first_inner[l + 1]));
  }

  bool exact;
  std::vector<std::uint64_t> next_child;   // per level l: the first_inner_child the next node of l must have
  std::vector<std::uint64_t> first_node;   // per level: the first node met when the count started unknown
  std::vector<std::uint64_t> first_child;  // and its first_inner_child
};

// The dense path: the subtree of the inner node `inner` at `level`, whose
// cube at (x, y, z) lies wholly inside the box, descended without frames or
// box clipping, in octant order, every node word checked (§8.3, §8.4).
// `Access::values8` hands over the eight values of a level-(target-1) node
// at once, and a sink that takes octets writes them as one 2x2x2 cube.
template <class Access, class Sink>
struct DenseDescent {
  Access& access;
  const VolumeLayout& layout;
  const LevelRanges& ranges;
  unsigned target;
  Sink& sink;
  NodeNumbering& numbering;

  void operator()(unsigned level, std::uint64_t inner, std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
    const std::uint64_t word = access.node_word(inner);
    check_node_word(layout, ranges, level, inner, word);
    numbering.check(level, inner, word);
    const std::uint64_t values = 1 + 8 * inner;
    if (level + 1 == target) {
      std::uint32_t bits[8];
      access.values8(values, bits);
      put_octet(sink, x, y, z, [&bits](unsigned c) { return bits[c]; });
      return;
    }
    const unsigned mask = child_mask(word);
    std::uint64_t next_inner = first_inner_child(word);
    if (level + 2 == target && mask != 0) {
      cube4(level, mask, values, next_inner, x, y, z);
      return;
    }
    const std::uint32_t half = std::uint32_t{1} << (target - level - 1);
    for (unsigned c = 0; c < 8; ++c) {
      const std::uint32_t cx = x + ((c & 1u) ? half : 0), cy = y + ((c & 2u) ? half : 0),
                          cz = z + ((c & 4u) ? half : 0);
      if ((mask >> c) & 1u)
        (*this)(level + 1, next_inner++, cx, cy, cz);
      else
        sink(Box{{cx, cy, cz}, {cx + half, cy + half, cz + half}}, access.value_bits(values + c));
    }
  }

  // A cube of 4^3 voxels: its inner children's node words are consecutive,
  // and so are their 8 values each. Each taken as one run from its decoded
  // block (where it lies in one) rather than looked up node by node; every
  // word is still checked, in the same order, before any of their values is
  // read. A run's bytes stay valid only until the next lookup, which may
  // load a block and let another go: nothing else is looked up while one is
  // in use.
  void cube4(unsigned level, unsigned mask, std::uint64_t values, std::uint64_t next_inner, std::uint32_t x,
             std::uint32_t y, std::uint32_t z) const {
    const unsigned count = popcount8(mask);
    const std::uint8_t* words = access.run(2, next_inner, count);
    std::uint64_t child_words[8];
    for (unsigned k = 0; k < count; ++k) {
      const std::uint64_t child = next_inner + k;
      child_words[k] = words ? ivol::layout::load<std::uint64_t>(words + 8 * k) : access.node_word(child);
      check_node_word(layout, ranges, level + 1, child, child_words[k]);
      numbering.check(level + 1, child, child_words[k]);
    }
    auto corner = [&](unsigned c, std::uint32_t* at) {
      at[0] = x + ((c & 1u) ? 2 : 0);
      at[1] = y + ((c & 2u) ? 2 : 0);
      at[2] = z + ((c & 4u) ? 2 : 0);
    };
    for (unsigned c = 0; c < 8; ++c) {  // the leaves among the children: 2^3 voxels each
      if ((mask >> c) & 1u) continue;
      std::uint32_t at[3];
      corner(c, at);
      sink(Box{{at[0], at[1], at[2]}, {at[0] + 2, at[1] + 2, at[2] + 2}}, access.value_bits(values + c));
    }
    const std::size_t width = access.value_width();
    const std::uint8_t* leaves = access.run(3, 1 + 8 * next_inner, 8 * std::uint64_t{count});
    if constexpr (TakesCubes<std::remove_const_t<Sink>>::value)
      if (count == 8 && leaves && width == 2 && sink.cube(x, y, z, leaves)) return;
    unsigned k = 0;
    for (unsigned c = 0; c < 8; ++c) {
      if (!((mask >> c) & 1u)) continue;
      std::uint32_t at[3];
      corner(c, at);
      const std::uint64_t child_values = 1 + 8 * (next_inner + k);
      const std::uint8_t* run = leaves ? leaves + 8 * k * width : nullptr;
      ++k;
      // Read straight from the decoded block: values copied into an
      // array first cost a store-forwarding stall at every node.
      if (!run) {
        std::uint32_t bits[8];
        access.values8(child_values, bits);
        put_octet(sink, at[0], at[1], at[2], [&bits](unsigned v) { return bits[v]; });
      } else if (width == 2) {
        put_octet(sink, at[0], at[1], at[2],
                  [run](unsigned v) { return std::uint32_t{ivol::layout::load<std::uint16_t>(run + 2 * v)}; });
      } else {
        put_octet(sink, at[0], at[1], at[2], [run](unsigned v) { return ivol::layout::load<std::uint32_t>(run + 4 * v); });
      }
    }
  }
};

// Calls sink(region, bits) for every leaf (or node of the target level) that
// meets `box`, with `region` the part of the box it covers, in the
// coordinates of level of detail `lod`. With `salvage`, a node or value that
// cannot be read (damaged block, broken rule) does not stop the walk: the
// region takes the value of the nearest readable ancestor (its average), and
// the damage is logged.
// Where a node's cube lies wholly inside the box (and no salvage), its
// subtree is descended without frames or box clipping (the dense path: a
// whole or large read of a scan, whose leaves are mostly single voxels), in
// the same order and with the same checks; `Access::values8` hands over the
// eight values of a level-(target-1) node at once, and a sink that takes
// octets writes them as one 2x2x2 cube.
template <class Access, class Sink>
void walk_box(Access& access, const VolumeLayout& layout, const LevelRanges& ranges, const Box& box, unsigned lod,
              Sink&& sink, SalvageLog* salvage = nullptr) {
  const unsigned target = layout.depth - lod;
  const Box whole = full_box(layout.dims, lod);
  NodeNumbering numbering(ranges, target, whole.lo == box.lo && whole.hi == box.hi);
  struct Frame {
    unsigned level;
    std::uint32_t i, j, k;
    std::uint64_t value_index;
    std::uint64_t inner;
    std::uint32_t fallback;  // bits of the nearest readable ancestor (salvage)
  };
  auto log = [&](const Box& region, unsigned level, const Error& e) {
    salvage->add(region, level, e.what());
    numbering.exact = false;  // a skipped subtree's children are not counted
  };
  // A value, or in salvage mode the fallback when it cannot be read.
  auto value_or = [&](std::uint64_t index, std::uint32_t fallback, const Box& region, unsigned level) {
    if (!salvage) return access.value_bits(index);
    if (const Error* known = access.known_failure(3, index)) {
      log(region, level, *known);
      return fallback;
    }
    try {
      return access.value_bits(index);
    } catch (const Error& e) {
      log(region, level, e);
      return fallback;
    }
  };
  const DenseDescent<Access, std::remove_reference_t<Sink>> dense{access, layout, ranges, target, sink, numbering};
  std::vector<Frame> stack;
  stack.push_back({0, 0, 0, 0, 0, layout.inner_count[0] ? 0 : kNoInner, 0});
  while (!stack.empty()) {
    const Frame f = stack.back();
    stack.pop_back();
    const std::uint64_t side = std::uint64_t{1} << (target - f.level);
    Box region;
    const std::uint64_t origin[3] = {f.i * side, f.j * side, f.k * side};
    bool meets = true;
    for (int a = 0; a < 3; ++a) {
      const std::uint64_t lo = std::max<std::uint64_t>(origin[a], box.lo[a]);
      const std::uint64_t hi = std::min<std::uint64_t>(origin[a] + side, box.hi[a]);
      if (lo >= hi) {
        meets = false;
        break;
      }
      region.lo[a] = static_cast<std::uint32_t>(lo);
      region.hi[a] = static_cast<std::uint32_t>(hi);
    }
    if (!meets) continue;
    if (!salvage && f.inner != kNoInner && f.level < target && region.lo[0] == origin[0] && region.lo[1] == origin[1] &&
        region.lo[2] == origin[2] && region.hi[0] - origin[0] == side && region.hi[1] - origin[1] == side &&
        region.hi[2] - origin[2] == side) {
      dense(f.level, f.inner, region.lo[0], region.lo[1], region.lo[2]);
      continue;
    }
    if (f.inner == kNoInner || f.level == target) {
      sink(region, value_or(f.value_index, f.fallback, region, f.level));
      continue;
    }
    // In salvage mode, read this node's own average first: it stands in for
    // whatever below it cannot be read.
    const std::uint32_t own = salvage ? value_or(f.value_index, f.fallback, region, f.level) : 0;
    std::uint64_t word;
    if (salvage)
      if (const Error* known = access.known_failure(2, f.inner)) {
        log(region, f.level, *known);
        sink(region, own);
        continue;
      }
    try {
      word = access.node_word(f.inner);
      check_node_word(layout, ranges, f.level, f.inner, word);
      numbering.check(f.level, f.inner, word);
    } catch (const Error& e) {
      if (!salvage) throw;
      log(region, f.level, e);
      sink(region, own);
      continue;
    }
    const unsigned mask = child_mask(word);
    const std::uint64_t first = first_inner_child(word);
    if (f.level + 1 == target) {
      // The children are at the target level: report them directly instead
      // of pushing eight frames (most of the work of a full-resolution read).
      const std::uint32_t half = static_cast<std::uint32_t>(side / 2);
      for (unsigned c = 0; c < 8; ++c) {
        Box child = region;
        bool inside = true;
        for (int a = 0; a < 3; ++a) {
          const std::uint64_t lo = origin[a] + (((c >> a) & 1u) ? half : 0);
          child.lo[a] = static_cast<std::uint32_t>(std::max<std::uint64_t>(lo, region.lo[a]));
          child.hi[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(lo + half, region.hi[a]));
          inside = inside && child.lo[a] < child.hi[a];
        }
        if (inside) sink(child, value_or(1 + 8 * f.inner + c, own, child, f.level + 1));
      }
      continue;
    }
    // Push in reverse so that children are visited in octant order, which
    // keeps block accesses sequential within each level.
    for (int c = 7; c >= 0; --c) {
      const auto cu = static_cast<unsigned>(c);
      const std::uint64_t child_inner = (mask >> cu) & 1u ? first + popcount8(mask & ((1u << cu) - 1u)) : kNoInner;
      stack.push_back({f.level + 1, 2 * f.i + (cu & 1u), 2 * f.j + ((cu >> 1) & 1u), 2 * f.k + ((cu >> 2) & 1u),
                       1 + 8 * f.inner + cu, child_inner, own});
    }
  }
  if (numbering.exact) numbering.check_totals(layout, ranges);
}

// Writes `bits` (width bytes each) or physical floats into a [z][y][x] buffer
// over `box`, for the region a walk reports.
template <class T>
void fill_region(T* out, const Box& box, const Box& region, T value) {
  const std::uint64_t nx = box.hi[0] - box.lo[0];
  const std::uint64_t ny = box.hi[1] - box.lo[1];
  if (region.hi[0] - region.lo[0] == 1 && region.hi[1] - region.lo[1] == 1 && region.hi[2] - region.lo[2] == 1) {
    out[((region.lo[2] - box.lo[2]) * ny + (region.lo[1] - box.lo[1])) * nx + (region.lo[0] - box.lo[0])] = value;
    return;  // most leaves of a full-resolution read are single voxels
  }
  for (std::uint32_t z = region.lo[2]; z < region.hi[2]; ++z)
    for (std::uint32_t y = region.lo[1]; y < region.hi[1]; ++y) {
      T* row = out + ((z - box.lo[2]) * ny + (y - box.lo[1])) * nx + (region.lo[0] - box.lo[0]);
      std::fill(row, row + (region.hi[0] - region.lo[0]), value);
    }
}

}  // namespace ivol::detail
