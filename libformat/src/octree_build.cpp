// Bottom-up construction of the pointer-packed octree from a dense volume.
//
// A depth-first walk in octant order appends each inner node's word to its
// level, and its eight children's values to the next level, when the node is
// finished. Nodes of one level are thereby appended in Morton order, which is
// the breadth-first order of the spec (§8.3); the first_inner_child fields
// are filled in afterwards from the masks. The subtrees below level 2 are
// built in parallel and concatenated in Morton order.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <thread>
#include <type_traits>

#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/error.hpp"

namespace ivol {
namespace {

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

// keep.any(level, i, j, k): does node (i, j, k) of `level` hold a voxel whose
// full resolution must be kept? An OR-pyramid of the keep mask.
class KeepPyramid {
 public:
  KeepPyramid(const std::uint8_t* mask, const Dims& dims, unsigned depth)
      : mask_(mask), depth_(depth), levels_(depth), dims_(depth + 1) {
    for (unsigned l = 0; l <= depth; ++l) dims_[l] = lod_dims(dims, depth - l);
    for (int l = static_cast<int>(depth) - 1; l >= 0; --l) {
      const Dims& d = dims_[l];
      auto& level = levels_[l];
      level.assign(voxel_count(d), 0);
      for (std::uint32_t k = 0; k < d[2]; ++k)
        for (std::uint32_t j = 0; j < d[1]; ++j)
          for (std::uint32_t i = 0; i < d[0]; ++i) {
            std::uint8_t any = 0;
            for (unsigned c = 0; c < 8 && !any; ++c)
              any = child_any(static_cast<unsigned>(l) + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u),
                              2 * k + ((c >> 2) & 1u));
            level[(std::uint64_t{k} * d[1] + j) * d[0] + i] = any;
          }
    }
  }

  bool any(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    return child_any(level, i, j, k) != 0;
  }

 private:
  std::uint8_t child_any(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k) const {
    const Dims& d = dims_[level];
    if (i >= d[0] || j >= d[1] || k >= d[2]) return 0;
    const std::uint64_t idx = (std::uint64_t{k} * d[1] + j) * d[0] + i;
    if (level == depth_) return mask_[idx] ? 1 : 0;
    return levels_[level][idx];
  }

  const std::uint8_t* mask_;
  unsigned depth_;
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

  // A node without kept voxels becomes one leaf holding their mean.
  NodeResult coarsen(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, BuildStats& stats) const {
    const Dims& d = layout_.dims;
    const std::uint64_t side = std::uint64_t{1} << (layout_.depth - level);
    const std::uint64_t lo[3] = {i * side, j * side, k * side};
    const std::uint64_t hi[3] = {std::min<std::uint64_t>(d[0], lo[0] + side),
                                 std::min<std::uint64_t>(d[1], lo[1] + side),
                                 std::min<std::uint64_t>(d[2], lo[2] + side)};
    double sum = 0.0;
    std::uint64_t count = 0;
    bool uniform = true;
    const Source first = data_[(lo[2] * d[1] + lo[1]) * d[0] + lo[0]];
    for (std::uint64_t z = lo[2]; z < hi[2]; ++z)
      for (std::uint64_t y = lo[1]; y < hi[1]; ++y) {
        const Source* row = data_ + (z * d[1] + y) * d[0];
        for (std::uint64_t x = lo[0]; x < hi[0]; ++x) {
          sum += static_cast<double>(row[x]);
          uniform = uniform && row[x] == first;
        }
        count += hi[0] - lo[0];
      }
    NodeResult r;
    r.weight = count;
    r.bits = uniform ? encode_source(first)
                     : encode_value(layout_.encoding, to_stored_domain(sum / static_cast<double>(count)));
    r.mean = decode_value(layout_.encoding, r.bits);
    if (!uniform) stats.coarsened = true;
    const double stored = layout_.physical(r.mean);
    for (std::uint64_t z = lo[2]; z < hi[2]; ++z)
      for (std::uint64_t y = lo[1]; y < hi[1]; ++y) {
        const Source* row = data_ + (z * d[1] + y) * d[0];
        for (std::uint64_t x = lo[0]; x < hi[0]; ++x) {
          const double err = std::fabs(stored - source_physical(row[x]));
          if (err > stats.max_abs_error) stats.max_abs_error = err;
        }
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
      if (identity_ && layout_.encoding == ValueEncoding::Binary16) return float_to_binary16(v);
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
    const Source v = data_[(std::uint64_t{z} * d[1] + y) * d[0] + x];
    NodeResult r;
    r.bits = encode_source(v);
    r.mean = decode_value(layout_.encoding, r.bits);
    r.weight = 1;
    note_error(v, r.bits, stats);
    return r;
  }

  const Source* data_;
  BuildOptions options_;
  const KeepPyramid* keep_;
  VolumeLayout layout_;
  bool identity_ = true;
};

std::uint32_t morton_index(unsigned bits, std::uint32_t i, std::uint32_t j, std::uint32_t k) {
  std::uint32_t t = 0;
  for (int b = static_cast<int>(bits) - 1; b >= 0; --b)
    t = (t << 3) | ((i >> b) & 1u) | (((j >> b) & 1u) << 1) | (((k >> b) & 1u) << 2);
  return t;
}

template <typename Source, typename Stored>
class ParallelBuild {
 public:
  ParallelBuild(const Builder<Source, Stored>& builder, unsigned threads)
      : b_(builder), depth_(builder.layout().depth), split_(depth_ >= 3 ? 2u : 0u) {
    const std::uint32_t task_count = 1u << (3 * split_);
    results_.resize(task_count);
    arrays_.reserve(task_count);
    for (std::uint32_t t = 0; t < task_count; ++t) arrays_.emplace_back(depth_);
    stats_.resize(task_count);
    std::atomic<std::uint32_t> next{0};
    auto work = [&] {
      for (std::uint32_t t; (t = next.fetch_add(1)) < task_count;) {
        std::uint32_t i = 0, j = 0, k = 0;
        for (unsigned b = 0; b < split_; ++b) {
          const std::uint32_t c = (t >> (3 * (split_ - 1 - b))) & 7u;
          i = (i << 1) | (c & 1u);
          j = (j << 1) | ((c >> 1) & 1u);
          k = (k << 1) | ((c >> 2) & 1u);
        }
        results_[t] = b_.build(split_, i, j, k, arrays_[t], stats_[t]);
      }
    };
    std::vector<std::thread> pool;
    const unsigned n = std::max(1u, std::min(threads, task_count));
    for (unsigned w = 1; w < n; ++w) pool.emplace_back(work);
    work();
    for (auto& th : pool) th.join();
  }

  // Builds the levels above the split from the subtrees' results.
  NodeResult top(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, LevelArrays<Stored>& out,
                 BuildStats& stats) const {
    if (level == split_) return results_[morton_index(split_, i, j, k)];
    if (b_.layout().weight(level, i, j, k) == 0) return NodeResult{};
    if (!b_.keeps(level, i, j, k)) return b_.coarsen(level, i, j, k, stats);
    NodeResult child[8];
    for (unsigned c = 0; c < 8; ++c)
      child[c] = top(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u), out, stats);
    return b_.combine(level, child, b_.layout().weight(level, i, j, k), out, stats);
  }

  unsigned split() const { return split_; }
  std::vector<LevelArrays<Stored>>& arrays() { return arrays_; }
  BuildStats stats() const {
    BuildStats s;
    for (const auto& t : stats_) s.merge(t);
    return s;
  }

 private:
  const Builder<Source, Stored>& b_;
  unsigned depth_;
  unsigned split_;
  std::vector<NodeResult> results_;
  std::vector<LevelArrays<Stored>> arrays_;
  std::vector<BuildStats> stats_;
};

template <typename Source, typename Stored>
BuildResult build(const Source* data, const Dims& dims, const BuildOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  for (auto n : dims)
    if (n == 0 || n > (1u << 31))
      throw Error(ErrorClass::InvalidArgument, "build_octree: each dimension must be 1 .. 2^31");
  if (!std::isfinite(options.value_scale) || options.value_scale == 0.0 || !std::isfinite(options.value_offset))
    throw Error(ErrorClass::InvalidArgument, "build_octree: value scale must be finite and non-zero, offset finite");

  const unsigned depth = depth_for(dims);
  std::unique_ptr<KeepPyramid> keep;
  if (options.keep_mask) keep = std::make_unique<KeepPyramid>(options.keep_mask, dims, depth);
  const Builder<Source, Stored> builder(data, dims, options, keep.get());

  unsigned threads = options.threads ? options.threads : std::thread::hardware_concurrency();
  ParallelBuild<Source, Stored> parallel(builder, std::max(1u, threads));
  LevelArrays<Stored> top(depth);
  BuildStats stats = parallel.stats();
  const NodeResult root = parallel.top(0, 0, 0, 0, top, stats);

  // Concatenate the levels: those above the split come from `top`, the rest
  // from the subtrees in Morton order.
  VolumeLayout layout = builder.layout();
  layout.inner_count.assign(depth + 1, 0);
  auto level_nodes = [&](unsigned l, auto&& visit) {
    if (l < parallel.split())
      visit(top.nodes[l]);
    else
      for (auto& a : parallel.arrays()) visit(a.nodes[l]);
  };
  auto level_values = [&](unsigned l, auto&& visit) {
    if (l <= parallel.split())
      visit(top.values[l]);
    else
      for (auto& a : parallel.arrays()) visit(a.values[l]);
  };
  for (unsigned l = 0; l <= depth; ++l)
    level_nodes(l, [&](const std::vector<std::uint64_t>& v) { layout.inner_count[l] += v.size(); });
  if (!root.inner) std::fill(layout.inner_count.begin(), layout.inner_count.end(), 0);

  std::vector<std::uint64_t> nodes;
  nodes.reserve(layout.total_inner());
  std::vector<std::uint8_t> values;
  const std::size_t width = sizeof(Stored);
  values.reserve(layout.total_values() * width);
  auto append_value = [&](Stored v) {
    const std::size_t at = values.size();
    values.resize(at + width);
    std::memcpy(values.data() + at, &v, width);
  };
  append_value(static_cast<Stored>(root.bits));
  if (root.inner) {
    std::uint64_t next_child = 1;
    for (unsigned l = 0; l <= depth; ++l) {
      level_nodes(l, [&](std::vector<std::uint64_t>& v) {
        for (std::uint64_t word : v) {
          nodes.push_back(make_node_word(child_mask(word), next_child));
          next_child += static_cast<unsigned>(__builtin_popcount(child_mask(word)));
        }
        std::vector<std::uint64_t>().swap(v);
      });
      if (l == 0) continue;
      level_values(l, [&](std::vector<Stored>& v) {
        const std::size_t at = values.size();
        values.resize(at + v.size() * width);
        std::memcpy(values.data() + at, v.data(), v.size() * width);
        std::vector<Stored>().swap(v);
      });
    }
  }

  BuildResult result;
  result.octree = Octree(std::move(layout), std::move(nodes), std::move(values));
  result.max_abs_error = stats.max_abs_error;
  result.lossless = stats.max_abs_error == 0.0 && !stats.coarsened;
  result.kept_voxels = stats.kept + (depth == 0 ? 1 : 0);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

template <typename Source>
BuildResult build_any(const Source* data, const Dims& dims, const BuildOptions& options) {
  if (options.encoding == ValueEncoding::Float32) return build<Source, std::uint32_t>(data, dims, options);
  return build<Source, std::uint16_t>(data, dims, options);
}

}  // namespace

BuildResult build_octree(const float* data, const Dims& dims, const BuildOptions& options) {
  return build_any(data, dims, options);
}

BuildResult build_octree(const std::uint16_t* data, const Dims& dims, const BuildOptions& options) {
  return build_any(data, dims, options);
}

}  // namespace ivol
