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
#include "octree_builder.hpp"
#include "thread_parts.hpp"

namespace ivol {
namespace {

using detail::Builder;
using detail::BuildStats;
using detail::KeepPyramid;
using detail::LevelArrays;
using detail::morton_index;
using detail::NodeResult;

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
        std::uint32_t i, j, k;
        detail::morton_decode(split_, t, i, j, k);
        results_[t] = b_.build(split_, i, j, k, arrays_[t], stats_[t]);
      }
    };
    detail::run_parts(std::max(1u, std::min(threads, task_count)), [&](unsigned) { work(); });
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
        if (!v.empty()) std::memcpy(values.data() + at, v.data(), v.size() * width);
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
