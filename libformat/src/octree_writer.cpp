// Writes an in-memory octree level by level from the root down (spec §15):
// the values of level l, then its nodes. Blocks are compressed in parallel in
// small batches and appended in order, so memory stays bounded by a batch.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>

#include "ivol/error.hpp"
#include "ivol/writer.hpp"

namespace ivol {
namespace {

struct PendingBlock {
  Stream stream;
  unsigned level;
  std::uint64_t first_element;
  std::uint32_t element_count;
  std::size_t width;
  const void* data;
};

std::vector<PendingBlock> plan_blocks(const Octree& octree, std::uint32_t block_bytes) {
  const VolumeLayout& layout = octree.layout();
  const std::size_t value_width = encoding_width(layout.encoding);
  std::vector<PendingBlock> plan;
  auto split = [&](Stream stream, unsigned level, std::uint64_t first, std::uint64_t count, std::size_t width,
                   const std::uint8_t* base) {
    const std::uint64_t per_block = std::max<std::uint64_t>(1, block_bytes / width);
    for (std::uint64_t at = 0; at < count; at += per_block) {
      const auto n = static_cast<std::uint32_t>(std::min(per_block, count - at));
      plan.push_back({stream, level, first + at, n, width, base + (first + at) * width});
    }
  };
  const auto* values = octree.value_bytes().data();
  const auto* nodes = reinterpret_cast<const std::uint8_t*>(octree.nodes().data());
  for (unsigned l = 0; l <= layout.depth; ++l) {
    split(Stream::Values, l, layout.first_value(l), layout.level_values(l), value_width, values);
    split(Stream::Nodes, l, layout.first_inner(l), layout.inner_count[l], 8, nodes);
  }
  return plan;
}

}  // namespace

WriteStats write_octree(const Octree& octree, const Metadata& metadata, const std::string& path,
                        const WriteOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (options.block_bytes < 8 || options.block_bytes > (64u << 20))
    throw Error(ErrorClass::InvalidArgument, "write: block size must be 8 B .. 64 MiB");
  const std::vector<PendingBlock> plan = plan_blocks(octree, options.block_bytes);
  FileWriter writer(path, octree.layout());

  const unsigned threads = std::max(1u, options.threads ? options.threads : std::thread::hardware_concurrency());
  const std::size_t batch = 4 * threads;
  std::vector<EncodedBlock> encoded(batch);
  WriteStats stats;
  for (std::size_t begin = 0; begin < plan.size(); begin += batch) {
    const std::size_t end = std::min(plan.size(), begin + batch);
    std::atomic<std::size_t> next{begin};
    std::exception_ptr failure;
    std::mutex failure_mutex;
    auto work = [&] {
      for (std::size_t i; (i = next.fetch_add(1)) < end;) {
        const PendingBlock& b = plan[i];
        try {
          encoded[i - begin] =
              encode_block(b.stream, b.level, b.first_element, b.element_count, b.width, b.data, options);
        } catch (...) {
          std::lock_guard<std::mutex> lock(failure_mutex);
          failure = std::current_exception();
        }
      }
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < std::min<std::size_t>(threads, end - begin); ++t) pool.emplace_back(work);
    work();
    for (auto& th : pool) th.join();
    if (failure) std::rethrow_exception(failure);
    for (std::size_t i = begin; i < end; ++i) {
      writer.append(encoded[i - begin]);
      stats.decoded_bytes += std::uint64_t{plan[i].element_count} * plan[i].width;
    }
  }
  writer.finish(metadata, octree.layout().inner_count);
  stats.file_bytes = writer.bytes_written();
  stats.block_count = writer.block_count();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace ivol
