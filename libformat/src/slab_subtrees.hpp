// Building one writer slab's subtrees: the code that both the streaming
// writer's add_slab and OctreeSlabBuilder (a slab built away from the writer,
// on another rank of a distributed run) run, so that a slab built either way
// gives the same subtrees. Also the wire form of a built slab. Internal.
#pragma once

#include <atomic>
#include <cmath>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "ivol/error.hpp"
#include "ivol/streaming_writer.hpp"
#include "octree_builder.hpp"
#include "thread_parts.hpp"

namespace ivol::detail {

inline void check_streaming_options(const Dims& dims, const StreamingOptions& options) {
  for (auto n : dims)
    if (n == 0 || n > (1u << 31))
      throw Error(ErrorClass::InvalidArgument, "streaming: each dimension must be 1 .. 2^31");
  if (!std::isfinite(options.build.value_scale) || options.build.value_scale == 0.0 ||
      !std::isfinite(options.build.value_offset))
    throw Error(ErrorClass::InvalidArgument, "streaming: value scale must be finite and non-zero, offset finite");
}

// How a volume is cut into slabs of `slab_slices` and each slab into
// subtrees of that side; the same for every writer and builder given the
// same dims and thickness.
struct SlabGrid {
  Dims dims{};
  std::uint32_t slab_slices = 1;
  unsigned depth = 0;
  unsigned subtree_level = 0;  // the level of the subtrees' roots
  unsigned levels = 1;         // levels subtree_level .. depth
  std::uint32_t grid[3] = {1, 1, 1};

  SlabGrid(const Dims& volume, std::uint32_t slab) : dims(volume), slab_slices(slab), depth(depth_for(volume)) {
    unsigned s = 0;
    while ((1u << s) < slab) ++s;
    subtree_level = depth - s;
    levels = depth - subtree_level + 1;
    for (int a = 0; a < 3; ++a) grid[a] = (dims[a] + slab - 1) / slab;
  }
  std::uint32_t slab_count() const { return grid[2]; }
  std::uint32_t subtrees_per_slab() const { return grid[0] * grid[1]; }
  std::uint32_t first_slice(std::uint32_t slab) const { return slab * slab_slices; }
  std::uint32_t slices(std::uint32_t slab) const { return std::min(slab_slices, dims[2] - first_slice(slab)); }
};

// What the levels above a subtree need of it.
struct SubtreeRecord {
  NodeResult root;
  RegionStats stats;  // with a keep mask only: then the levels above may coarsen
  bool any_kept = false;
};

// What the streaming writer holds per subtree until finish(): its record
// and spill offset, and per level its nodes' and values' element counts and
// stored bytes. (dims / slab)^3 subtrees: at 2048^3 with 8-slice slabs,
// 16.8 M of them took 3.4 GB (issue 23), more than the slabs themselves.
inline std::uint64_t subtree_index_bytes(const Dims& dims, std::uint32_t slab) {
  const SlabGrid grid(dims, slab);
  const std::uint64_t subtrees = std::uint64_t{grid.grid[0]} * grid.grid[1] * grid.grid[2];
  const std::uint64_t per_subtree = sizeof(SubtreeRecord) + sizeof(std::uint64_t) + std::uint64_t{grid.levels} * 2 * 2 * 8;
  return subtrees * per_subtree;
}

// Slab thickness in slices: the one asked for (a power of two), or the
// largest whose float32 samples and subtree index (subtree_index_bytes) fit
// the budget (at least 8 slices, or the volume); when none fits, the one
// that needs least of the two together.
inline std::uint32_t choose_slab_slices(const Dims& dims, const StreamingOptions& options) {
  const unsigned depth = depth_for(dims);
  const std::uint32_t side = 1u << depth;
  if (options.slab_slices) {
    const std::uint32_t s = options.slab_slices;
    if ((s & (s - 1)) != 0) throw Error(ErrorClass::InvalidArgument, "streaming: slab_slices must be a power of two");
    return std::min(s, side);
  }
  const std::uint64_t slice_bytes = std::uint64_t{dims[0]} * dims[1] * 4;
  std::uint32_t best_fit = 0, least = 0;
  std::uint64_t least_bytes = ~std::uint64_t{0};
  for (std::uint64_t s = std::min<std::uint32_t>(8, side); s <= side; s *= 2) {
    const auto slices = static_cast<std::uint32_t>(s);
    const std::uint64_t bytes = s * slice_bytes + subtree_index_bytes(dims, slices);
    if (bytes <= options.slab_budget_bytes) best_fit = slices;
    if (bytes < least_bytes) least_bytes = bytes, least = slices;
  }
  return best_fit ? best_fit : least;
}

// Receives subtree n = j * grid[0] + i of a slab, once built: its record and
// its node words and values of levels subtree_level .. depth. Called on the
// building threads, several subtrees at once (so that a sink can compress
// them in parallel): the sink locks whatever it shares.
template <typename Stored>
using SubtreeSink = std::function<void(std::uint32_t n, const SubtreeRecord&, const LevelArrays<Stored>&)>;

// Builds every subtree of slab k on `threads` threads. `samples` (and `keep`,
// when given) hold the slab's slices. Returns the slab's build statistics.
template <typename Source, typename Stored>
BuildStats build_slab_subtrees(Builder<Source, Stored>& builder, const SlabGrid& grid, std::uint32_t k,
                               const Source* samples, const std::uint8_t* keep, unsigned threads,
                               const SubtreeSink<Stored>& sink) {
  const std::uint32_t z0 = grid.first_slice(k);
  std::unique_ptr<KeepPyramid> pyramid;
  if (keep)
    pyramid = std::make_unique<KeepPyramid>(keep, Dims{grid.dims[0], grid.dims[1], grid.slices(k)}, grid.depth, z0,
                                            grid.subtree_level);
  builder.set_slab(samples, z0, pyramid.get());
  std::atomic<std::uint32_t> next{0};
  std::mutex failure_mutex;
  std::exception_ptr failure;
  std::vector<BuildStats> thread_stats(threads);
  auto work = [&](unsigned t) {
    for (std::uint32_t n; (n = next.fetch_add(1)) < grid.subtrees_per_slab();) {
      try {
        const std::uint32_t i = n % grid.grid[0], j = n / grid.grid[0];
        LevelArrays<Stored> arrays(grid.depth);
        SubtreeRecord record;
        record.root = builder.build(grid.subtree_level, i, j, k, arrays, thread_stats[t]);
        if (keep) record.stats = builder.region_stats(grid.subtree_level, i, j, k);
        record.any_kept = !pyramid || pyramid->any(grid.subtree_level, i, j, k);
        sink(n, record, arrays);
      } catch (...) {
        std::lock_guard<std::mutex> lock(failure_mutex);
        failure = std::current_exception();
      }
    }
  };
  detail::run_parts(threads, work);
  builder.set_slab(nullptr, 0, nullptr);
  if (failure) std::rethrow_exception(failure);
  BuildStats stats;
  for (const auto& s : thread_stats) stats.merge(s);
  return stats;
}

// The wire form of a built slab (ivol/octree_slab_builder.hpp), in the host's
// byte order (the ranks of one run share an architecture): a header, one
// record per subtree, per subtree and level the counts of node words and
// values, then the subtrees' data, each subtree's levels in turn (node words,
// then values), at the offset its record gives.
struct BuiltSlabHeader {
  char magic[8];  // "ivolslab"
  std::uint32_t version;
  std::uint32_t slab;
  std::uint32_t dims[3];
  std::uint32_t slab_slices;
  std::uint8_t encoding;
  std::uint8_t source_is_float;
  std::uint8_t with_keep;
  std::uint8_t coarsened;
  std::uint32_t unused;  // zero
  double value_scale;
  double value_offset;
  double max_abs_error;
  std::uint64_t kept;
  std::uint64_t subtree_count;
  std::uint64_t data_bytes;
};
static_assert(sizeof(BuiltSlabHeader) == 88, "BuiltSlabHeader travels as bytes");
constexpr std::uint32_t kBuiltSlabVersion = 1;

struct BuiltSubtreeRecord {
  std::uint32_t bits;
  std::uint8_t inner;
  std::uint8_t has_nan;
  std::uint8_t any_kept;
  std::uint8_t unused;
  double mean;
  std::uint64_t weight;
  double sum;
  double min;
  double max;
  std::uint64_t data_offset;  // from the start of the data
};
static_assert(sizeof(BuiltSubtreeRecord) == 56, "BuiltSubtreeRecord travels as bytes");

inline BuiltSubtreeRecord to_wire(const SubtreeRecord& r, std::uint64_t data_offset) {
  return BuiltSubtreeRecord{r.root.bits,   r.root.inner, r.stats.has_nan, r.any_kept,  0,          r.root.mean,
                            r.root.weight, r.stats.sum,  r.stats.min,     r.stats.max, data_offset};
}

inline SubtreeRecord from_wire(const BuiltSubtreeRecord& w) {
  SubtreeRecord r;
  r.root = NodeResult{w.bits, w.inner != 0, w.mean, w.weight};
  r.stats.sum = w.sum;
  r.stats.min = w.min;
  r.stats.max = w.max;
  r.stats.has_nan = w.has_nan != 0;
  r.any_kept = w.any_kept != 0;
  return r;
}

}  // namespace ivol::detail
