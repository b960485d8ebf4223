// Decoded blocks shared by the threads of one parallel read (whole_level.hpp),
// and the walk's block access for one of those threads. Internal to
// libformat.
//
// A Reader's cache and hints serve one thread; a read on several threads
// takes its blocks from a SharedBlocks instead: each block is read once
// (the file by one thread at a time), then checked and decoded by the
// thread that first needs it, while the others wait for it or walk on.
// Its errors (a CRC, a zstd frame, a missing element) reach every thread
// that needs the block, as the same ivol::Error.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <vector>

#include "reader_impl.hpp"

namespace ivol::detail {

class SharedBlocks {
 public:
  // Holds up to `budget` decoded bytes beyond the blocks in use.
  SharedBlocks(Reader::Impl& impl, std::uint64_t budget) : impl_(impl), budget_(budget) {}
  SharedBlocks(const SharedBlocks&) = delete;
  SharedBlocks& operator=(const SharedBlocks&) = delete;

  // Block `index` decoded: thread-safe; throws the block's error.
  BlockData get(std::size_t index);
  // Once the threads are done: the blocks decoded and those that failed,
  // into the Reader's statistics and its list of failed blocks.
  void hand_over();

 private:
  struct Entry {
    BlockData data;
    std::optional<Error> error;
    bool ready = false;
    std::list<std::size_t>::iterator position;  // in order_, once ready
  };
  void evict_over_budget();
  // A buffer of `size` bytes: one let go by an evicted block, or new.
  std::vector<std::uint8_t> reuse(std::size_t size);
  static constexpr std::size_t kSpareBuffers = 64;

  Reader::Impl& impl_;
  std::uint64_t budget_;
  std::mutex mutex_;       // entries_, order_, held_, decoded_
  std::mutex file_mutex_;  // the Reader's file, read by one thread at a time
  std::condition_variable ready_;
  std::unordered_map<std::size_t, std::shared_ptr<Entry>> entries_;
  std::list<std::size_t> order_;  // ready entries, most recently used first
  std::uint64_t held_ = 0;
  std::vector<std::vector<std::uint8_t>> spare_;  // buffers of evicted blocks
  std::uint64_t decoded_ = 0;
};

// tree_walk.hpp's Access for one thread of a parallel read: the elements of
// the nodes and values streams, found from the block last used at each
// level (a walk stays in one block per level for long stretches).
class ThreadAccess {
 public:
  ThreadAccess(const Reader::Impl& impl, SharedBlocks& blocks);

  std::uint64_t node_word(std::uint64_t index) { return layout::load<std::uint64_t>(element(2, index)); }
  std::uint32_t value_bits(std::uint64_t index) {
    const std::uint8_t* p = element(3, index);
    return width_ == 4 ? layout::load<std::uint32_t>(p) : std::uint32_t{layout::load<std::uint16_t>(p)};
  }
  void values8(std::uint64_t index, std::uint32_t* bits) {
    const std::uint8_t* p = run(3, index, 8);
    for (unsigned c = 0; c < 8; ++c)
      bits[c] = !p           ? value_bits(index + c)
                : width_ == 4 ? layout::load<std::uint32_t>(p + 4 * c)
                              : std::uint32_t{layout::load<std::uint16_t>(p + 2 * c)};
  }
  // `count` elements from `index` on where one decoded block holds them
  // all, else null; valid until the next lookup.
  const std::uint8_t* run(std::uint8_t stream, std::uint64_t index, std::uint64_t count) {
    const std::uint8_t* p = element(stream, index);
    const Hint& h = hints_[stream - 2][last_[stream - 2][0]];
    return h.first + h.count - index < count ? nullptr : p;
  }
  std::size_t value_width() const { return width_; }
  const Error* known_failure(std::uint8_t, std::uint64_t) const { return nullptr; }  // no salvage here

 private:
  struct Hint {
    std::uint64_t first = 0;
    std::uint64_t count = 0;
    BlockData data;
  };
  // The block last used, then the one before: the dense walk alternates
  // between two levels of each stream (a node's word, its children's).
  const std::uint8_t* element(std::uint8_t stream, std::uint64_t index) {
    std::size_t* recent = last_[stream - 2];
    const std::vector<Hint>& hints = hints_[stream - 2];
    const std::size_t width = stream == 2 ? 8 : width_;
    const Hint& h = hints[recent[0]];
    if (h.data && index - h.first < h.count) return h.data->data() + (index - h.first) * width;
    const Hint& g = hints[recent[1]];
    if (g.data && index - g.first < g.count) {
      std::swap(recent[0], recent[1]);
      return g.data->data() + (index - g.first) * width;
    }
    return element_elsewhere(stream, index);
  }
  [[gnu::noinline]] const std::uint8_t* element_elsewhere(std::uint8_t stream, std::uint64_t index);

  const Reader::Impl& impl_;
  SharedBlocks& blocks_;
  std::size_t width_;
  std::vector<Hint> hints_[2];  // nodes, values: one per octree level
  std::size_t last_[2][2] = {{0, 0}, {0, 0}};  // per stream: the hint used last, and the one before
};

}  // namespace ivol::detail
