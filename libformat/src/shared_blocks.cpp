#include "shared_blocks.hpp"

#include <algorithm>
#include <new>

#include "brick_grid.hpp"

namespace ivol::detail {

BlockData SharedBlocks::get(std::size_t index) {
  std::unique_lock<std::mutex> lock(mutex_);
  // Failed in an earlier read of this Reader: fails the same way again.
  if (const auto failed = impl_.failures.find(index); failed != impl_.failures.end()) throw failed->second;
  auto found = entries_.find(index);
  if (found != entries_.end()) {
    // Held here while waiting: the entry may be evicted once ready.
    const std::shared_ptr<Entry> e = found->second;
    ready_.wait(lock, [&] { return e->ready; });  // another thread decodes it
    if (e->error) throw *e->error;
    if (const auto still = entries_.find(index); still != entries_.end() && still->second == e)
      order_.splice(order_.begin(), order_, e->position);
    return e->data;
  }
  const auto entry = std::make_shared<Entry>();
  entries_.emplace(index, entry);
  lock.unlock();

  const BlockInfo& b = impl_.info.blocks[index];
  const std::size_t width = stream_width(b.stream, impl_.info.layout.encoding);
  BlockData data;
  std::optional<Error> error;
  try {
    // The stored bytes into this thread's buffer (blocks are small: a
    // buffer per block would cost its allocation and page faults).
    thread_local std::vector<std::uint8_t> stored;
    if (stored.size() < b.stored_size) stored.resize(b.stored_size);
    {
      std::lock_guard<std::mutex> file_lock(file_mutex_);
      impl_.file.read(b.file_offset, stored.data(), b.stored_size);
    }
    auto decoded = std::make_shared<std::vector<std::uint8_t>>(reuse(std::size_t{b.element_count} * width));
    decode_stored_into(impl_.file.path(), b, index, width, impl_.info.framed(),
                       brick_of_block(impl_.info.layout, b.stream, b.level, b.first_element), stored.data(),
                       b.stored_size, decoded->data());
    data = std::move(decoded);
  } catch (const Error& e) {
    error = e;
  } catch (const std::bad_alloc&) {
    error = Error(ErrorClass::LimitExceeded,
                  impl_.file.path() + ": block " + std::to_string(index) + " cannot be decoded: out of memory");
  }

  lock.lock();
  Entry& e = *entry;
  e.ready = true;
  e.data = data;
  e.error = error;
  if (data) {  // a failed block stays listed, never evicted: it must fail again
    order_.push_front(index);
    e.position = order_.begin();
    held_ += data->size();
    ++decoded_;
  }
  evict_over_budget();
  lock.unlock();
  ready_.notify_all();
  if (error) throw *error;
  return data;
}

void SharedBlocks::evict_over_budget() {
  // The least recently used first; the entry just used stays, at the front.
  while (held_ > budget_ && order_.size() > 1) {
    const std::size_t victim = order_.back();
    const std::shared_ptr<Entry>& entry = entries_.at(victim);
    BlockData& data = entry->data;
    held_ -= data->size();
    // No thread holds it or waits for it: its bytes serve the next block of
    // its size (the blocks of a file are mostly of one size), without
    // allocating, zeroing and faulting in new memory. get() made it
    // non-const.
    if (entry.use_count() == 1 && data.use_count() == 1 && spare_.size() < kSpareBuffers)
      spare_.push_back(std::move(const_cast<std::vector<std::uint8_t>&>(*data)));
    order_.pop_back();
    entries_.erase(victim);
  }
}

std::vector<std::uint8_t> SharedBlocks::reuse(std::size_t size) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!spare_.empty() && spare_.back().size() == size) {
      std::vector<std::uint8_t> buffer = std::move(spare_.back());
      spare_.pop_back();
      return buffer;
    }
  }
  return std::vector<std::uint8_t>(size);
}

void SharedBlocks::hand_over() {
  impl_.stats.blocks_decoded += decoded_;
  for (const auto& [index, e] : entries_)
    if (e->error) impl_.failures.emplace(index, *e->error);
}

ThreadAccess::ThreadAccess(const Reader::Impl& impl, SharedBlocks& blocks)
    : impl_(impl), blocks_(blocks), width_(stream_width(3, impl.info.layout.encoding)) {
  for (auto& h : hints_) h.resize(impl.info.layout.depth + 1);
}

const std::uint8_t* ThreadAccess::element_elsewhere(std::uint8_t stream, std::uint64_t index) {
  const std::size_t width = stream == 2 ? 8 : width_;
  std::vector<Hint>& hints = hints_[stream - 2];
  std::size_t* recent = last_[stream - 2];
  for (std::size_t l = 0; l < hints.size(); ++l)
    if (hints[l].data && index - hints[l].first < hints[l].count) {
      recent[1] = recent[0];
      recent[0] = l;
      return hints[l].data->data() + (index - hints[l].first) * width;
    }
  const auto& list = impl_.stream_blocks[stream];
  const auto& blocks = impl_.info.blocks;
  auto it = std::upper_bound(list.begin(), list.end(), index,
                             [&](std::uint64_t e, std::size_t b) { return e < blocks[b].first_element; });
  if (it == list.begin() || index - blocks[*(it - 1)].first_element >= blocks[*(it - 1)].element_count)
    impl_.missing(stream, it == list.begin() ? 0 : blocks[*(it - 1)].first_element + blocks[*(it - 1)].element_count,
                  it == list.end() ? nullptr : &blocks[*it]);
  const BlockInfo& b = blocks[*(it - 1)];
  // The block is looked up before the hint is replaced: a block that fails
  // leaves the hints as they were.
  BlockData data = blocks_.get(*(it - 1));
  Hint& h = hints[std::min<std::size_t>(b.level, hints.size() - 1)];
  h = Hint{b.first_element, b.element_count, std::move(data)};
  const auto l = static_cast<std::size_t>(&h - hints.data());
  if (recent[0] != l) recent[1] = recent[0];
  recent[0] = l;
  return h.data->data() + (index - b.first_element) * width;
}

}  // namespace ivol::detail
