// Fetch planning: a read first finds the blocks it touches, then fetches
// them together (ByteSource::prefetch merges adjacent ranges into one
// request and runs independent ones in parallel) and decodes them on several
// threads, each once, into the Reader's block cache; the walk that follows
// finds every block there. Over HTTP a slice then costs one round of
// requests per octree level instead of one per 64 KiB page it meets; on a
// local disk a large read decodes its blocks in parallel.
#include <algorithm>
#include <atomic>
#include <optional>
#include <thread>

#include "brick_grid.hpp"
#include "reader_impl.hpp"
#include "thread_parts.hpp"

namespace ivol {

namespace {

// Enough decoded bytes to be worth more threads than one.
constexpr std::uint64_t kParallelBytes = 1u << 20;
// An octree plan follows at most this many nodes a level, and no more than
// the two levels it holds at once fit in the block cache's capacity (the
// cache could not hold the blocks of more anyway; at 2^21 the lists took
// 100 MB, beyond a small --memory); a read that meets more (most of a large
// volume) is walked block by block instead.
constexpr std::size_t kMaxPlannedNodes = std::size_t{1} << 21;
constexpr std::size_t kMinPlannedNodes = std::size_t{1} << 12;
// Stored bytes fetched and decoded at a time.
constexpr std::uint64_t kChunkBytes = 16u << 20;

unsigned decode_threads(std::size_t blocks, std::uint64_t bytes, unsigned configured) {
  if (blocks < 2 || bytes < kParallelBytes) return 1;
  const unsigned hardware = configured ? configured : std::min(8u, std::max(1u, std::thread::hardware_concurrency()));
  return static_cast<unsigned>(std::min<std::size_t>(blocks, hardware));
}

}  // namespace

void Reader::Impl::load_blocks(std::vector<std::size_t> blocks) {
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  // Those not held, not failed, and as many as the cache holds (more would
  // push out the first before the walk uses them).
  std::vector<std::size_t> todo;
  std::uint64_t decoded = 0;
  for (const std::size_t b : blocks) {
    if (b == SIZE_MAX || cache.contains(b) || failures.count(b)) continue;
    const BlockInfo& info_b = info.blocks[b];
    const std::uint64_t size =
        std::uint64_t{info_b.element_count} * detail::stream_width(info_b.stream, info.layout.encoding);
    if (decoded + size > cache.capacity()) break;
    decoded += size;
    todo.push_back(b);
  }
  // A chunk at a time, so that the ranges a remote source holds for the
  // reads that follow stay within its budget.
  for (std::size_t begin = 0; begin < todo.size();) {
    std::size_t end = begin;
    std::uint64_t stored_bytes = 0;
    while (end < todo.size() && (end == begin || stored_bytes + info.blocks[todo[end]].stored_size <= kChunkBytes))
      stored_bytes += info.blocks[todo[end++]].stored_size;
    load_chunk(std::vector<std::size_t>(todo.begin() + begin, todo.begin() + end));
    begin = end;
  }
}

void Reader::Impl::load_chunk(const std::vector<std::size_t>& todo) {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> ranges;
  ranges.reserve(todo.size());
  std::uint64_t decoded = 0;
  for (const std::size_t b : todo) {
    ranges.emplace_back(info.blocks[b].file_offset, info.blocks[b].stored_size);
    decoded +=
        std::uint64_t{info.blocks[b].element_count} * detail::stream_width(info.blocks[b].stream, info.layout.encoding);
  }
  file.prefetch(ranges);
  // Read in file order by this thread (the byte source is not thread-safe),
  // then checked and decoded in parallel.
  std::vector<std::vector<std::uint8_t>> stored(todo.size());
  std::vector<std::optional<Error>> errors(todo.size());
  for (std::size_t n = 0; n < todo.size(); ++n) {
    try {
      stored[n] = file.read(info.blocks[todo[n]].file_offset, info.blocks[todo[n]].stored_size);
    } catch (const Error& e) {
      errors[n] = e;
    }
  }
  std::vector<detail::BlockData> data(todo.size());
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t n; (n = next.fetch_add(1)) < todo.size();) {
      if (errors[n]) continue;
      const BlockInfo& b = info.blocks[todo[n]];
      try {
        data[n] = std::make_shared<const std::vector<std::uint8_t>>(detail::decode_stored_block(
            file.path(), b, todo[n], detail::stream_width(b.stream, info.layout.encoding), info.framed(),
            detail::brick_of_block(info.layout, b.stream, b.level, b.first_element), std::move(stored[n])));
      } catch (const Error& e) {
        errors[n] = e;
      }
    }
  };
  const unsigned threads = decode_threads(todo.size(), decoded, this->threads);
  detail::run_parts(threads, [&](unsigned) { work(); });
  for (std::size_t n = 0; n < todo.size(); ++n) {
    if (errors[n])
      failures.emplace(todo[n], *errors[n]);
    else
      remember(todo[n], data[n]);
  }
}

void Reader::Impl::plan_box(const Box& box, unsigned lod) {
  const VolumeLayout& v = info.layout;
  // The full-resolution voxels under the box.
  Box full;
  for (int a = 0; a < 3; ++a) {
    full.lo[a] = box.lo[a] << lod;
    full.hi[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(std::uint64_t{box.hi[a]} << lod, v.dims[a]));
  }
  std::vector<std::size_t> blocks;
  if (v.kind == StructureKind::Bricked && lod > 0 && stored_level(lod)) {
    // The stored level's bricks under the box (spec §8A.5), not the volume's.
    const detail::BrickGrid bricks(lod_dims(v.dims, lod), v.cell_log2);
    const auto slot = static_cast<std::uint8_t>(kStoredLevelSlot + lod);
    for (std::uint32_t k = box.lo[2] >> v.cell_log2; k <= (box.hi[2] - 1) >> v.cell_log2; ++k)
      for (std::uint32_t j = box.lo[1] >> v.cell_log2; j <= (box.hi[1] - 1) >> v.cell_log2; ++j)
        for (std::uint32_t i = box.lo[0] >> v.cell_log2; i <= (box.hi[0] - 1) >> v.cell_log2; ++i)
          blocks.push_back(block_of(slot, bricks.first_value(i, j, k)));
    load_blocks(std::move(blocks));
    return;
  }
  if (v.kind == StructureKind::Bricked) {
    const detail::BrickGrid bricks(v.dims, v.cell_log2);
    for (std::uint32_t k = full.lo[2] >> v.cell_log2; k <= (full.hi[2] - 1) >> v.cell_log2; ++k)
      for (std::uint32_t j = full.lo[1] >> v.cell_log2; j <= (full.hi[1] - 1) >> v.cell_log2; ++j)
        for (std::uint32_t i = full.lo[0] >> v.cell_log2; i <= (full.hi[0] - 1) >> v.cell_log2; ++i)
          blocks.push_back(block_of(3, bricks.first_value(i, j, k)));
    load_blocks(std::move(blocks));
    return;
  }
  if (v.kind == StructureKind::Regular) {
    // Each row of the box is a run of values: the blocks from its first to
    // its last.
    const auto& list = stream_blocks[3];
    for (std::uint64_t z = full.lo[2]; z < full.hi[2]; ++z)
      for (std::uint64_t y = full.lo[1]; y < full.hi[1]; ++y) {
        const std::uint64_t first = (z * v.dims[1] + y) * v.dims[0] + full.lo[0];
        const std::size_t a = block_of(3, first), b = block_of(3, first + (full.hi[0] - full.lo[0]) - 1);
        if (a == SIZE_MAX || b == SIZE_MAX) return;  // a gap: the walk reports it
        if (!blocks.empty() && blocks.back() == b) continue;
        auto at = std::find(list.begin(), list.end(), a);  // sorted by first element: a .. b
        for (; at != list.end(); ++at) {
          blocks.push_back(*at);
          if (*at == b) break;
        }
      }
    load_blocks(std::move(blocks));
    return;
  }
  if (v.kind != StructureKind::Octree) return;  // rectilinear and nested grids: read as walked
  if (v.inner_count[0] == 0) {
    load_blocks({block_of(3, 0)});
    return;
  }
  const unsigned target = v.depth - lod;
  const Box whole = full_box(v.dims, lod);
  if (whole.lo == box.lo && whole.hi == box.hi) {
    // The whole level: every block of the levels above it (nodes) and down
    // to it (values), without following the nodes one by one.
    for (const std::size_t b : stream_blocks[2])
      if (info.blocks[b].level < target) blocks.push_back(b);
    for (const std::size_t b : stream_blocks[3])
      if (info.blocks[b].level <= target) blocks.push_back(b);
    load_blocks(std::move(blocks));
    return;
  }
  // The block of `stream` holding `element`, the last one found first:
  // the children of neighbouring nodes mostly lie in one block.
  std::size_t last[2] = {SIZE_MAX, SIZE_MAX};
  auto block_holding = [&](std::uint8_t stream, std::uint64_t element) {
    std::size_t& hint_block = last[stream - 2];
    if (hint_block != SIZE_MAX &&
        element - info.blocks[hint_block].first_element < info.blocks[hint_block].element_count)
      return hint_block;
    return hint_block = block_of(stream, element);
  };
  // A level at a time: the nodes of level l meeting the box (their words
  // loaded with the values of the level before), their children that are
  // leaves or at the target level (values), and those that are inner
  // (nodes of level l + 1).
  struct Node {
    std::uint64_t inner;
    std::uint32_t i, j, k;
  };
  const std::size_t max_nodes = std::clamp<std::size_t>(static_cast<std::size_t>(cache.capacity() / (2 * sizeof(Node))),
                                                        kMinPlannedNodes, kMaxPlannedNodes);
  std::vector<Node> level{{0, 0, 0, 0}};
  try {
    load_blocks({block_of(2, 0)});
    for (unsigned l = 0; l < target && !level.empty(); ++l) {
      const std::uint64_t half = std::uint64_t{1} << (target - l - 1);
      std::vector<Node> next;
      for (const Node& n : level) {
        const std::uint64_t word = node_word(n.inner);
        detail::check_node_word(v, ranges, l, n.inner, word);
        const unsigned mask = child_mask(word);
        const std::uint64_t first = first_inner_child(word);
        if (l + 1 == target) {
          // The children are values, eight in a row: where the node's cube
          // lies inside the box, the blocks of the first and the last (a
          // large read meets millions of such nodes).
          const std::uint64_t side = 2 * half;
          const std::uint64_t at[3] = {n.i * side, n.j * side, n.k * side};
          bool inside = true;
          for (int a = 0; a < 3; ++a) inside = inside && at[a] >= box.lo[a] && at[a] + side <= box.hi[a];
          if (inside) {
            for (const std::uint64_t value : {1 + 8 * n.inner, 8 + 8 * n.inner}) {
              const std::size_t b = block_holding(3, value);
              if (blocks.empty() || blocks.back() != b) blocks.push_back(b);
            }
            continue;
          }
        }
        for (unsigned c = 0; c < 8; ++c) {
          const std::uint32_t ci = 2 * n.i + (c & 1u), cj = 2 * n.j + ((c >> 1) & 1u), ck = 2 * n.k + ((c >> 2) & 1u);
          const std::uint64_t origin[3] = {ci * half, cj * half, ck * half};
          bool meets = true;
          for (int a = 0; a < 3; ++a) meets = meets && origin[a] < box.hi[a] && origin[a] + half > box.lo[a];
          if (!meets) continue;
          const bool inner = (mask >> c) & 1u;
          if (inner && l + 1 < target) {
            const std::uint64_t index = first + detail::popcount8(mask & ((1u << c) - 1u));
            // More nodes than a plan follows: the walk reads the blocks
            // as it meets them (and the plan holds no list of millions).
            if (next.size() == max_nodes) return;
            next.push_back({index, ci, cj, ck});
            const std::size_t b = block_holding(2, index);
            if (blocks.empty() || blocks.back() != b) blocks.push_back(b);
          } else {
            const std::size_t b = block_holding(3, 1 + 8 * n.inner + c);
            if (blocks.empty() || blocks.back() != b) blocks.push_back(b);
          }
        }
      }
      load_blocks(std::move(blocks));
      blocks.clear();
      level = std::move(next);
    }
  } catch (const Error&) {
    // A damaged or malformed part: the walk meets it again, and reports it
    // (or salvages around it) as it does without a plan.
  }
}

}  // namespace ivol
