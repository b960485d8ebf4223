// A whole level of detail of an octree (a whole-volume read: numpy's f[:],
// `ivol extract`, `convert`) on several threads: the subtrees below level
// kSplitLevel are descended by the dense path of tree_walk.hpp one per task,
// each thread decoding the blocks it needs (shared_blocks.hpp). Internal
// to libformat.
//
// Every check of the one-thread walk is made: each node word against §8.3
// and §8.4 as it is met; the node numbering within each subtree as in
// walk_box, and across subtrees afterwards, in order, from the counts each
// task started and ended with at each level (so a DAG is refused as
// before); the level table's totals. A failure in any task (a damaged
// block, a broken rule) is thrown once the threads are done, the first in
// octant order; the output is then incomplete, as after any failed read.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <exception>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

#include "reader_impl.hpp"
#include "shared_blocks.hpp"
#include "tree_walk.hpp"

namespace ivol::detail {

// Subtrees rooted at this level (or above it, for shallow trees) are the
// tasks: 512 of them, enough to keep every thread busy to the end.
constexpr unsigned kSplitLevel = 3;
// Decoded bytes the threads share beyond those in use: blocks are met in
// file order, level by level, so a few MiB would do; a quarter of the cache,
// at most 32 MiB.
inline std::uint64_t shared_blocks_budget(std::uint64_t cache_bytes) {
  return std::min<std::uint64_t>(cache_bytes / 4, 32u << 20);
}

// Threads for a parallel read: ReaderOptions::threads, or the hardware's.
inline unsigned read_threads(unsigned configured) {
  if (configured) return configured;
  return std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
}

// The threads read_whole_level runs a read of `box` at `lod` on, or 0 where
// it does not serve it (the one-thread walk does). Memory stays within the
// Reader's cache budget (reader.hpp, Resources): the blocks the threads
// share, and each thread's block in use at each level of each stream,
// counted at the size of the largest block.
inline unsigned whole_level_threads(const Reader::Impl& impl, const Box& box, unsigned lod) {
  const VolumeLayout& v = impl.info.layout;
  if (v.kind != StructureKind::Octree || impl.info.salvage || is_remote(impl.file.path())) return 0;
  const Box whole = full_box(v.dims, lod);
  // A tree of two levels or fewer below the target is a few nodes.
  if (whole.lo != box.lo || whole.hi != box.hi || v.inner_count[0] == 0 || v.depth < lod + 3) return 0;
  std::uint64_t largest = 0;
  for (const std::uint8_t stream : {2, 3})
    for (const std::size_t b : impl.stream_blocks[stream])
      largest = std::max<std::uint64_t>(largest, std::uint64_t{impl.info.blocks[b].element_count} *
                                                     stream_width(stream, v.encoding));
  const std::uint64_t shared = shared_blocks_budget(impl.cache.capacity());
  const std::uint64_t per_thread = 2 * std::uint64_t{v.depth + 1} * largest;
  if (impl.cache.capacity() < shared + per_thread) return 0;
  return static_cast<unsigned>(
      std::min<std::uint64_t>(read_threads(impl.threads), (impl.cache.capacity() - shared) / per_thread));
}

template <class Sink>
void read_whole_level(Reader::Impl& impl, unsigned lod, Sink& sink, unsigned threads) {
  const VolumeLayout& v = impl.info.layout;
  const LevelRanges& ranges = impl.ranges;
  const unsigned target = v.depth - lod;
  const unsigned split = std::min(kSplitLevel, target - 2);

  // The nodes above the split level, one thread, in octant order: each
  // inner node at the split level is a task, each leaf above it a fill.
  struct Task {
    Box region;             // a fill: its region; a subtree: its cube
    std::uint64_t inner;    // the subtree's root at level `split`, or kNoInner
    std::uint32_t bits;     // a fill's value
  };
  std::vector<Task> tasks;
  NodeNumbering above(ranges, target, true);
  // The level's voxels: a cube may reach past them (padding, spec §8.2),
  // and one wholly past them is skipped, as walk_box skips what misses the
  // box (a node of padding alone is a leaf, §8.4).
  const Dims dims = lod_dims(v.dims, lod);
  auto outside = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return x >= dims[0] || y >= dims[1] || z >= dims[2];
  };
  auto clip = [&](Box b) {
    for (int a = 0; a < 3; ++a) b.hi[a] = std::min(b.hi[a], dims[a]);
    return b;
  };
  {
    ImplAccess access{&impl};
    auto descend = [&](auto& self, unsigned level, std::uint64_t inner, std::uint32_t x, std::uint32_t y,
                       std::uint32_t z) -> void {
      const std::uint64_t word = access.node_word(inner);
      check_node_word(v, ranges, level, inner, word);
      above.check(level, inner, word);
      const unsigned mask = child_mask(word);
      std::uint64_t next_inner = first_inner_child(word);
      const std::uint32_t half = std::uint32_t{1} << (target - level - 1);
      for (unsigned c = 0; c < 8; ++c) {
        const std::uint32_t cx = x + ((c & 1u) ? half : 0), cy = y + ((c & 2u) ? half : 0),
                            cz = z + ((c & 4u) ? half : 0);
        const Box cube{{cx, cy, cz}, {cx + half, cy + half, cz + half}};
        const bool inner_child = (mask >> c) & 1u;
        const std::uint64_t child = inner_child ? next_inner++ : kNoInner;
        if (outside(cx, cy, cz)) continue;
        if (!inner_child)
          tasks.push_back({clip(cube), kNoInner, access.value_bits(1 + 8 * inner + c)});
        else if (level + 1 == split)
          tasks.push_back({cube, child, 0});
        else
          self(self, level + 1, child, cx, cy, cz);
      }
    };
    descend(descend, 0, 0, 0, 0, 0);
  }

  // The subtrees on `threads` threads, taken in order.
  struct Outcome {
    std::vector<std::uint64_t> first_node, first_child, next_child;  // levels split .. target-1
    std::exception_ptr error;
  };
  std::vector<Outcome> outcomes(tasks.size());
  SharedBlocks blocks(impl, shared_blocks_budget(impl.cache.capacity()));
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr setup_error;  // a thread that could not start its work (out of memory)
  std::mutex setup_mutex;
  auto work_tasks = [&] {
    ThreadAccess access(impl, blocks);
    NodeNumbering numbering(ranges, target, true);
    const DenseDescent<ThreadAccess, Sink> dense{access, v, ranges, target, sink, numbering};
    // A subtree that reaches past the level's voxels: its nodes clipped as
    // walk_box clips them, down to those wholly inside (dense again).
    auto clipped = [&](auto& self, unsigned level, std::uint64_t inner, std::uint32_t x, std::uint32_t y,
                       std::uint32_t z) -> void {
      const std::uint32_t side = std::uint32_t{1} << (target - level);
      if (x + side <= dims[0] && y + side <= dims[1] && z + side <= dims[2]) {
        dense(level, inner, x, y, z);
        return;
      }
      const std::uint64_t word = access.node_word(inner);
      check_node_word(v, ranges, level, inner, word);
      numbering.check(level, inner, word);
      const unsigned mask = child_mask(word);
      std::uint64_t next_inner = first_inner_child(word);
      const std::uint32_t half = side / 2;
      for (unsigned c = 0; c < 8; ++c) {
        const std::uint32_t cx = x + ((c & 1u) ? half : 0), cy = y + ((c & 2u) ? half : 0),
                            cz = z + ((c & 4u) ? half : 0);
        const bool inner_child = (mask >> c) & 1u;
        const std::uint64_t child = inner_child ? next_inner++ : kNoInner;
        if (outside(cx, cy, cz)) continue;
        if (inner_child && level + 1 < target)
          self(self, level + 1, child, cx, cy, cz);
        else  // a leaf, or a node of the target level: its value
          sink(clip(Box{{cx, cy, cz}, {cx + half, cy + half, cz + half}}), access.value_bits(1 + 8 * inner + c));
      }
    };
    for (std::size_t n; !failed && (n = next.fetch_add(1)) < tasks.size();) {
      const Task& t = tasks[n];
      Outcome& out = outcomes[n];
      if (t.inner == kNoInner) {
        sink(t.region, t.bits);
        continue;
      }
      numbering.start_subtree(split);
      try {
        clipped(clipped, split, t.inner, t.region.lo[0], t.region.lo[1], t.region.lo[2]);
      } catch (...) {
        out.error = std::current_exception();
        failed = true;
      }
      out.first_node.assign(numbering.first_node.begin() + split, numbering.first_node.end());
      out.first_child.assign(numbering.first_child.begin() + split, numbering.first_child.end());
      out.next_child.assign(numbering.next_child.begin() + split, numbering.next_child.end());
    }
  };
  auto work = [&] {
    try {
      work_tasks();
    } catch (...) {
      std::lock_guard<std::mutex> lock(setup_mutex);
      if (!setup_error) setup_error = std::current_exception();
      failed = true;
    }
  };
  threads = static_cast<unsigned>(std::min<std::size_t>(threads, tasks.size()));
  std::vector<std::thread> pool;
  try {
    for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  } catch (const std::system_error&) {
    // No more threads to be had: those started and this one do the work.
  }
  work();
  for (std::thread& t : pool) t.join();
  blocks.hand_over();
  if (setup_error) std::rethrow_exception(setup_error);

  // The numbering across subtrees, in octant order: each one's first node
  // at a level continues the count the one before it ended with.
  for (std::size_t n = 0; n < tasks.size(); ++n) {
    if (tasks[n].inner == kNoInner) continue;
    const Outcome& out = outcomes[n];
    if (out.first_node.empty() && !out.error) break;  // not run: a task before it failed
    for (unsigned l = split; l < target; ++l) {
      const std::size_t k = l - split;
      if (out.first_node[k] == NodeNumbering::kUnknown) continue;  // no node of this level
      if (out.first_child[k] != above.next_child[l])
        fail_order(l, out.first_node[k], out.first_child[k], above.next_child[l], true);
      above.next_child[l] = out.next_child[k];
    }
    if (out.error) std::rethrow_exception(out.error);
  }
  above.check_totals(v, ranges);
}

}  // namespace ivol::detail
