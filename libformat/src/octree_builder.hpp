// The depth-first octree builder shared by build_octree (whole volumes in
// memory) and StreamingOctreeWriter (slabs of subtrees). Internal.
#pragma once

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/encoding.hpp"

namespace ivol::detail {

struct NodeResult {
  std::uint32_t bits = 0;
  bool inner = false;
  double mean = 0.0;  // m(node) of spec §10
  std::uint64_t weight = 0;
};

template <typename Stored>
struct LevelArrays {
  std::vector<std::vector<std::uint64_t>> nodes;
  std::vector<std::vector<Stored>> values;
  explicit LevelArrays(unsigned depth) : nodes(depth + 1), values(depth + 1) {}
};

struct BuildStats {
  double max_abs_error = 0.0;
  std::uint64_t kept = 0;
  bool coarsened = false;
  void merge(const BuildStats& o) {
    max_abs_error = std::max(max_abs_error, o.max_abs_error);
    kept += o.kept;
    coarsened = coarsened || o.coarsened;
  }
};

// Minimum and maximum order -0 below +0, so that a region holding both is
// not taken for uniform (its leaf would give every voxel one sign).
struct RegionStats {
  double sum = 0.0;
  double min = INFINITY;
  double max = -INFINITY;
  bool has_nan = false;
  static bool below(double a, double b) { return a < b || (a == b && std::signbit(a) && !std::signbit(b)); }
  void add(double v) {
    sum = sum + v;
    extend(v);
  }
  // The minimum, the maximum and the NaN flag alone.
  void extend(double v) {
    if (std::isnan(v)) {
      has_nan = true;
      return;
    }
    if (below(v, min)) min = v;
    if (below(max, v)) max = v;
  }
  void merge(const RegionStats& o) {
    sum = sum + o.sum;
    if (below(o.min, min)) min = o.min;
    if (below(max, o.max)) max = o.max;
    has_nan = has_nan || o.has_nan;
  }
  bool uniform() const { return !has_nan && min == max && std::signbit(min) == std::signbit(max); }
};

// keep.any(level, i, j, k): does node (i, j, k) of `level` hold a voxel whose
// full resolution must be kept? An OR-pyramid of the keep mask. The mask may
// cover a slab of the volume starting at slice `z_origin` (a multiple of the
// side of the nodes of `min_level`); then only levels >= min_level are asked.
class KeepPyramid {
 public:
  KeepPyramid(const std::uint8_t* mask, const Dims& mask_dims, unsigned depth, std::uint32_t z_origin = 0,
              unsigned min_level = 0)
      : mask_(mask), depth_(depth), z_origin_(z_origin), levels_(depth), dims_(depth + 1) {
    for (unsigned l = 0; l <= depth; ++l) dims_[l] = lod_dims(mask_dims, depth - l);
    for (int l = static_cast<int>(depth) - 1; l >= static_cast<int>(min_level); --l) {
      const Dims& d = dims_[l];
      auto& level = levels_[l];
      level.assign(voxel_count(d), 0);
      for (std::uint32_t k = 0; k < d[2]; ++k)
        for (std::uint32_t j = 0; j < d[1]; ++j)
          for (std::uint32_t i = 0; i < d[0]; ++i) {
            std::uint8_t any = 0;
            for (unsigned c = 0; c < 8 && !any; ++c)
              any = local_any(static_cast<unsigned>(l) + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u),
                              2 * k + ((c >> 2) & 1u));
            level[(std::uint64_t{k} * d[1] + j) * d[0] + i] = any;
          }
    }
  }

  bool any(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return local_any(level, i, j, k - (z_origin_ >> (depth_ - level))) != 0;
  }

 private:
  std::uint8_t local_any(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    const Dims& d = dims_[level];
    if (i >= d[0] || j >= d[1] || k >= d[2]) return 0;
    const std::uint64_t idx = (std::uint64_t{k} * d[1] + j) * d[0] + i;
    if (level == depth_) return mask_[idx] ? 1 : 0;
    return levels_[level][idx];
  }

  const std::uint8_t* mask_;
  unsigned depth_;
  std::uint32_t z_origin_;
  std::vector<std::vector<std::uint8_t>> levels_;
  std::vector<Dims> dims_;
};

template <typename Source, typename Stored>
class Builder {
 public:
  Builder(const Source* data, const Dims& dims, const BuildOptions& options, const KeepPyramid* keep)
      : data_(data), options_(options), keep_(keep) {
    layout_.dims = dims;
    layout_.depth = depth_for(dims);
    layout_.encoding = options.encoding;
    layout_.value_scale = options.value_scale;
    layout_.value_offset = options.value_offset;
    identity_ = options.value_scale == 1.0 && options.value_offset == 0.0;
  }

  const VolumeLayout& layout() const { return layout_; }

  // Points the builder at a slab of the volume: `data` holds slices
  // z_origin, z_origin + 1, ... (each size_y x size_x samples).
  void set_slab(const Source* data, std::uint32_t z_origin, const KeepPyramid* keep) {
    data_ = data;
    z_origin_ = z_origin;
    keep_ = keep;
  }

  NodeResult build(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, LevelArrays<Stored>& out,
                   BuildStats& stats) const {
    NodeResult r;
    r.weight = layout_.weight(level, i, j, k);
    if (r.weight == 0) return r;
    if (level == layout_.depth) return voxel(i, j, k, stats);
    if (!keeps(level, i, j, k)) return coarsen(level, i, j, k, stats);
    NodeResult child[8];
    for (unsigned c = 0; c < 8; ++c) {
      const std::uint32_t ci = 2 * i + (c & 1u);
      const std::uint32_t cj = 2 * j + ((c >> 1) & 1u);
      const std::uint32_t ck = 2 * k + ((c >> 2) & 1u);
      if (level + 1 == layout_.depth) {
        child[c].weight = layout_.weight(level + 1, ci, cj, ck);
        if (child[c].weight) child[c] = voxel(ci, cj, ck, stats);
      } else {
        child[c] = build(level + 1, ci, cj, ck, out, stats);
      }
    }
    return combine(level, child, r.weight, out, stats);
  }

  // False when a keep mask is given and the node holds no voxel to keep.
  bool keeps(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return !keep_ || keep_->any(level, i, j, k);
  }

  // Sum, minimum and maximum of the source values a node covers, summed
  // child by child in octant order, so that a node's sum does not depend on
  // how the volume was cut into slabs or subtrees.
  RegionStats region_stats(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    RegionStats r;
    const std::uint64_t weight = layout_.weight(level, i, j, k);
    if (weight == 0) return r;
    if (level == layout_.depth) {
      const Dims& d = layout_.dims;
      r.add(static_cast<double>(data_[(std::uint64_t{k - z_origin_} * d[1] + j) * d[0] + i]));
      return r;
    }
    const unsigned side_log2 = layout_.depth - level;
    if (side_log2 <= kBlockLog2 && weight == std::uint64_t{1} << (3 * side_log2))  // inside the volume whole
      return block_stats(side_log2, i << side_log2, j << side_log2, k << side_log2);
    for (unsigned c = 0; c < 8; ++c)
      r.merge(region_stats(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u)));
    return r;
  }

  // region_stats of a node of side 2^side_log2 ≤ 2^kBlockLog2 whose voxels
  // all lie in the volume, from (x0, y0, z0): the same numbers as the
  // recursion, without a call and a weight per voxel (which took a third of
  // an object-fidelity conversion's time). The sum is the recursion's,
  // operation for operation: a voxel's is 0 + v (+0 for −0), a node's adds
  // its children's to 0 in octant order (x, then y, then z), and since no
  // such sum is −0, 0 + the first child's is that sum. The minimum, the
  // maximum and the NaN flag do not depend on the order.
  RegionStats block_stats(unsigned side_log2, std::uint32_t x0, std::uint32_t y0, std::uint32_t z0) const {
    const Dims& d = layout_.dims;
    const std::uint32_t side = 1u << side_log2;
    RegionStats r;
    block_extremes(side, x0, y0, z0, r);
    // Sums level by level, in place: sums[(c·h + b)·h + a] for the nodes of
    // side 2 at first (h = side / 2 of them a row), then of side 4, ...
    double sums[(std::size_t{1} << (3 * kBlockLog2)) / 8];
    std::uint32_t h = side / 2;
    for (std::uint32_t c = 0; c < h; ++c)
      for (std::uint32_t b = 0; b < h; ++b) {
        // The four rows of voxels the nodes of this row of nodes cover.
        const Source* row[4];
        for (unsigned q = 0; q < 4; ++q)
          row[q] =
              data_ + (std::uint64_t{z0 + 2 * c + (q >> 1) - z_origin_} * d[1] + y0 + 2 * b + (q & 1u)) * d[0] + x0;
        double* out = sums + (std::size_t{c} * h + b) * h;
        for (std::uint32_t a = 0; a < h; ++a)
          out[a] = octant_sum([&](unsigned dx, unsigned dy, unsigned dz) {
            return 0.0 + static_cast<double>(row[2 * dz + dy][2 * a + dx]);
          });
      }
    for (; h > 1; h /= 2) {
      const std::uint32_t g = h / 2;
      auto child = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
        return sums[(std::size_t{c} * h + b) * h + a];
      };
      // Each parent is written after its children are read, at an index no
      // larger than theirs: in place.
      for (std::uint32_t c = 0; c < g; ++c)
        for (std::uint32_t b = 0; b < g; ++b)
          for (std::uint32_t a = 0; a < g; ++a)
            sums[(std::size_t{c} * g + b) * g + a] = octant_sum(
                [&](unsigned dx, unsigned dy, unsigned dz) { return child(2 * a + dx, 2 * b + dy, 2 * c + dz); });
    }
    r.sum = sums[0];
    return r;
  }

  // Σ of child(dx, dy, dz) over the eight octants, added one by one in
  // octant order (x, then y, then z) from the first.
  template <class Child>
  static double octant_sum(Child&& child) {
    double t = child(0u, 0u, 0u);
    for (unsigned c = 1; c < 8; ++c) t = t + child(c & 1u, (c >> 1) & 1u, (c >> 2) & 1u);
    return t;
  }

  // The minimum and maximum (-0 below +0) and whether a NaN is among the
  // voxels of a block of block_stats, in one loop that vectorises: a
  // float's bits as a signed integer whose order is the floats' (negative
  // ones with their other bits reversed), NaNs left out.
  void block_extremes(std::uint32_t side, std::uint32_t x0, std::uint32_t y0, std::uint32_t z0, RegionStats& r) const {
    const Dims& d = layout_.dims;
    if constexpr (std::is_same_v<Source, float>) {
      std::int32_t lo = INT32_MAX, hi = INT32_MIN;
      std::uint32_t nan = 0;
      for (std::uint32_t z = z0; z < z0 + side; ++z)
        for (std::uint32_t y = y0; y < y0 + side; ++y) {
          const float* row = data_ + (std::uint64_t{z - z_origin_} * d[1] + y) * d[0] + x0;
          for (std::uint32_t x = 0; x < side; ++x) {
            std::uint32_t bits;
            std::memcpy(&bits, row + x, 4);
            const std::uint32_t is_nan = (bits & 0x7FFFFFFFu) > 0x7F800000u;
            const auto key = static_cast<std::int32_t>(bits ^ ((0u - (bits >> 31)) & 0x7FFFFFFFu));
            lo = std::min(lo, is_nan ? INT32_MAX : key);
            hi = std::max(hi, is_nan ? INT32_MIN : key);
            nan |= is_nan;
          }
        }
      r.has_nan = nan != 0;
      if (lo <= hi) {  // else every voxel is NaN: min and max stay as they are
        auto value = [](std::int32_t key) {
          auto bits = static_cast<std::uint32_t>(key);
          bits ^= (0u - (bits >> 31)) & 0x7FFFFFFFu;
          float f;
          std::memcpy(&f, &bits, 4);
          return static_cast<double>(f);
        };
        r.min = value(lo);
        r.max = value(hi);
      }
    } else {
      for (std::uint32_t z = z0; z < z0 + side; ++z)
        for (std::uint32_t y = y0; y < y0 + side; ++y) {
          const Source* row = data_ + (std::uint64_t{z - z_origin_} * d[1] + y) * d[0] + x0;
          for (std::uint32_t x = 0; x < side; ++x) r.extend(static_cast<double>(row[x]));
        }
    }
  }

  // A node without kept voxels becomes one leaf holding their mean.
  NodeResult coarsen(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, BuildStats& stats) const {
    return leaf_from_stats(region_stats(level, i, j, k), layout_.weight(level, i, j, k), stats);
  }

  // The leaf that replaces `weight` source voxels with these statistics: their
  // value when they are all equal, else their mean; the error it makes is
  // largest at the smallest or the largest source value.
  NodeResult leaf_from_stats(const RegionStats& region, std::uint64_t weight, BuildStats& stats) const {
    NodeResult r;
    r.weight = weight;
    const bool uniform = region.uniform();
    r.bits = uniform ? encode_source(static_cast<Source>(region.min))
                     : encode_value(layout_.encoding, to_stored_domain(region.sum / static_cast<double>(weight)));
    r.mean = decode_value(layout_.encoding, r.bits);
    if (!uniform) stats.coarsened = true;
    if (region.min <= region.max) {
      const double stored = layout_.physical(r.mean);
      const double err = std::max(std::fabs(stored - source_physical(static_cast<Source>(region.min))),
                                  std::fabs(stored - source_physical(static_cast<Source>(region.max))));
      if (err > stats.max_abs_error) stats.max_abs_error = err;
    }
    return r;
  }

  // Decides between a merged leaf and an inner node once the children are
  // known; appends an inner node to the arrays.
  NodeResult combine(unsigned level, const NodeResult* child, std::uint64_t weight, LevelArrays<Stored>& out,
                     BuildStats& stats) const {
    bool mergeable = true;
    bool have = false;
    std::uint32_t common = 0;
    for (unsigned c = 0; c < 8 && mergeable; ++c) {
      if (child[c].weight == 0) continue;
      if (child[c].inner || (have && child[c].bits != common)) {
        mergeable = false;
      } else if (!have) {
        common = child[c].bits;
        have = true;
      }
    }
    if (mergeable) return NodeResult{common, false, decode_value(layout_.encoding, common), weight};

    std::uint8_t mask = 0;
    double acc = 0.0;
    double total = 0.0;  // spec §10 accumulates the weights in binary64 too
    for (unsigned c = 0; c < 8; ++c) {
      if (child[c].inner) mask = static_cast<std::uint8_t>(mask | (1u << c));
      out.values[level + 1].push_back(static_cast<Stored>(child[c].bits));
      if (child[c].weight > 0) {
        acc = acc + static_cast<double>(child[c].weight) * child[c].mean;
        total = total + static_cast<double>(child[c].weight);
        if (level + 1 == layout_.depth) ++stats.kept;
      }
    }
    out.nodes[level].push_back(make_node_word(mask, 0));
    const double mean = acc / total;
    return NodeResult{encode_value(layout_.encoding, mean), true, mean, weight};
  }

 private:
  // uint16 sources stored as uint16 are the codes themselves (scale and offset
  // only say what they mean); any other source holds physical values.
  bool source_is_codes() const {
    return std::is_same_v<Source, std::uint16_t> && layout_.encoding == ValueEncoding::UInt16;
  }

  double to_stored_domain(double source) const {
    if (identity_ || source_is_codes()) return source;
    return (source - layout_.value_offset) / layout_.value_scale;
  }

  double source_physical(Source v) const {
    return source_is_codes() ? layout_.physical(static_cast<double>(v)) : static_cast<double>(v);
  }

  std::uint32_t encode_source(Source v) const {
    if constexpr (std::is_same_v<Source, float>) {
      // A leaf keeps a NaN's payload (what a binary16 source held survives).
      if (identity_ && layout_.encoding == ValueEncoding::Binary16) return float_to_binary16_keep_nan(v);
      if (identity_ && layout_.encoding == ValueEncoding::Float32) {
        std::uint32_t bits;
        std::memcpy(&bits, &v, 4);
        return bits;
      }
    } else {
      if (source_is_codes()) return v;
    }
    return encode_value(layout_.encoding, to_stored_domain(static_cast<double>(v)));
  }

  void note_error(Source source, std::uint32_t bits, BuildStats& stats) const {
    const double err = std::fabs(layout_.physical(decode_value(layout_.encoding, bits)) - source_physical(source));
    if (err > stats.max_abs_error) stats.max_abs_error = err;  // NaN never compares greater
  }

  NodeResult voxel(std::uint32_t x, std::uint32_t y, std::uint32_t z, BuildStats& stats) const {
    const Dims& d = layout_.dims;
    const Source v = data_[(std::uint64_t{z - z_origin_} * d[1] + y) * d[0] + x];
    NodeResult r;
    r.bits = encode_source(v);
    r.mean = decode_value(layout_.encoding, r.bits);
    r.weight = 1;
    note_error(v, r.bits, stats);
    return r;
  }

  // Nodes of up to 2^kBlockLog2 voxels a side take block_stats (its sums,
  // 4 KiB, on the stack).
  static constexpr unsigned kBlockLog2 = 4;

  const Source* data_;
  std::uint32_t z_origin_ = 0;  // the slice data_ starts with
  BuildOptions options_;
  const KeepPyramid* keep_;
  VolumeLayout layout_;
  bool identity_ = true;
};

// The node coordinates of Morton index t among the nodes of level `bits`.
inline void morton_decode(unsigned bits, std::uint64_t t, std::uint32_t& i, std::uint32_t& j, std::uint32_t& k) {
  i = j = k = 0;
  for (unsigned b = 0; b < bits; ++b) {
    const auto c = static_cast<std::uint32_t>((t >> (3 * (bits - 1 - b))) & 7u);
    i = (i << 1) | (c & 1u);
    j = (j << 1) | ((c >> 1) & 1u);
    k = (k << 1) | ((c >> 2) & 1u);
  }
}

inline std::uint32_t morton_index(unsigned bits, std::uint32_t i, std::uint32_t j, std::uint32_t k) {
  std::uint32_t t = 0;
  for (int b = static_cast<int>(bits) - 1; b >= 0; --b)
    t = (t << 3) | ((i >> b) & 1u) | (((j >> b) & 1u) << 1) | (((k >> b) & 1u) << 2);
  return t;
}

}  // namespace ivol::detail
