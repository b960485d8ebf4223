// The Reader's state, shared with check_file. Internal to libformat.
#pragma once

#include <algorithm>
#include <cstring>
#include <map>
#include <optional>
#include <unordered_map>

#include "block_reader.hpp"
#include "file_index.hpp"
#include "grid_structure.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "layout.hpp"
#include "salvage.hpp"
#include "tree_walk.hpp"

namespace ivol {

struct Reader::Impl {
  detail::RandomAccessFile file;
  std::string salvaged_metadata;  // the metadata text a salvaging open found; before `info`, which fills it
  FileInfo info;
  Metadata metadata;
  std::string metadata_problem;  // Reader::metadata_problem
  detail::LevelRanges ranges;
  detail::BlockCache cache;
  IoStats stats;
  std::uint64_t grid_lod_voxels = 0;                // ReaderOptions::grid_lod_voxels
  unsigned threads = 0;                             // ReaderOptions::threads
  std::uint64_t bytes_baseline = 0;                 // file.bytes_read at the last reset
  std::uint64_t requests_baseline = 0;              // file.requests() at the last reset
  std::uint64_t fetched_baseline = 0;               // file.bytes_fetched() at the last reset
  std::unordered_map<std::size_t, Error> failures;  // blocks that failed their checks
  // The gaps of a salvaged index met so far (known_failure), by stream and
  // first missing element.
  mutable std::map<std::pair<std::uint8_t, std::uint64_t>, Error> gaps;
  std::optional<detail::GridStructure> grid;        // structures of spec §8A
  // Blocks of the known streams, sorted by first element, by slot: the
  // stream's number, or for a bricked grid's stored level of detail k
  // (stream 7, spec §8A.5) kStoredLevelSlot + k, since the levels number
  // their elements each from 0.
  static constexpr std::uint8_t kStoredLevelSlot = 8;
  static constexpr std::size_t kSlots = kStoredLevelSlot + 32;
  std::vector<std::size_t> stream_blocks[kSlots];
  // The block last used for each stream and level, held here as well as in
  // the cache: walks stay within one block per level for long stretches, and
  // then find their element without a cache lookup.
  struct Hint {
    std::size_t block = SIZE_MAX;
    std::uint64_t first = 0;
    std::uint64_t count = 0;
    detail::BlockData data;
  };
  std::vector<Hint> hint[kSlots];
  std::size_t last_level[kSlots] = {};  // the hint that served the last lookup
  std::size_t width_[kSlots] = {};      // bytes of an element of each slot, looked up once

  Impl(const std::string& path, const ReaderOptions& options)
      : file(path),
        info(detail::read_or_salvage(file, options.salvage, salvaged_metadata)),
        ranges(info.layout),
        cache(options.cache_bytes),
        grid_lod_voxels(options.grid_lod_voxels),
        threads(options.threads) {
    for (std::size_t b = 0; b < info.blocks.size(); ++b) {
      const BlockInfo& blk = info.blocks[b];
      if (!detail::is_known_stream(blk.stream, info.layout.kind)) continue;
      // A stored level is used only as a whole: a salvaged file's may not be.
      if (blk.stream == 7 && !info.salvage && options.stored_levels)
        stream_blocks[kStoredLevelSlot + blk.level].push_back(b);
      if (blk.stream < kStoredLevelSlot && blk.stream != 7) stream_blocks[blk.stream].push_back(b);
    }
    for (auto& list : stream_blocks)
      std::sort(list.begin(), list.end(), [&](std::size_t a, std::size_t b) {
        return info.blocks[a].first_element < info.blocks[b].first_element;
      });
    for (auto& h : hint) h.assign(info.layout.depth + 1, Hint{});
    for (std::uint8_t s = 1; s < 6; ++s) width_[s] = detail::stream_width(s, info.layout.encoding);
    for (std::size_t s = kStoredLevelSlot; s < kSlots; ++s) width_[s] = width_[3];
    if (info.salvage) {
      // Checked when salvaged; none survived: the defaults (info.salvage says so).
      if (!salvaged_metadata.empty()) metadata = Metadata::parse(salvaged_metadata);
      if (info.salvage->metadata == "missing") metadata_problem = "no metadata block survived";
    } else {
      try {
        // Exactly its bytes over HTTP, not the pages around it (a writer
        // that learns the metadata last puts it before the index).
        const BlockInfo& m = info.blocks[stream_blocks[1].front()];
        file.prefetch({{m.file_offset, m.stored_size}});
        const auto text = block(stream_blocks[1].front());
        metadata = Metadata::parse(std::string(text->begin(), text->end()));
      } catch (const Error& e) {
        if (!options.salvage) throw Error(e.error_class(), file.path() + ": " + e.what());
        // A salvaging reader reads the values without it; the defaults stand in.
        metadata_problem = e.what();
      }
    }
    if (info.layout.kind != StructureKind::Octree) load_grid();
  }

  // The borders or cell words of a grid structure (spec §8A), checked.
  void load_grid() {
    std::vector<std::uint32_t> borders;
    std::vector<std::uint64_t> cells;
    for (std::size_t b : stream_blocks[4]) {
      const auto data = block(b);
      const std::size_t at = borders.size();
      borders.resize(at + data->size() / 4);
      std::memcpy(borders.data() + at, data->data(), data->size());
    }
    for (std::size_t b : stream_blocks[5]) {
      const auto data = block(b);
      const std::size_t at = cells.size();
      cells.resize(at + data->size() / 8);
      std::memcpy(cells.data() + at, data->data(), data->size());
    }
    std::uint64_t values = 0;
    for (std::size_t b : stream_blocks[3]) values += info.blocks[b].element_count;
    if (info.salvage) values = detail::GridStructure::kValuesUnknown;  // gaps are read as missing
    try {
      grid.emplace(info.layout, std::move(borders), std::move(cells), values, file.path());
    } catch (const Error& e) {
      if (!info.salvage) throw;
      throw Error(ErrorClass::Truncated, info.salvage->reason +
                                             "; nothing can be salvaged: the grid's borders or cell words did "
                                             "not all survive: " +
                                             e.what());
    }
  }

  detail::BlockData block(std::size_t index) {
    if (auto hit = cache.find(index)) {
      ++stats.cache_hits;
      return hit;
    }
    // A block that failed once fails the same way again: do not re-read it
    // (a salvaging walk meets it many times).
    if (const auto failed = failures.find(index); failed != failures.end()) throw failed->second;
    const BlockInfo& b = info.blocks[index];
    detail::BlockData data;
    try {
      data = std::make_shared<const std::vector<std::uint8_t>>(detail::read_and_decode_block(
          file, b, index, detail::stream_width(b.stream, info.layout.encoding), true, info.framed(),
          detail::brick_of_block(info.layout, b.stream, b.level, b.first_element)));
    } catch (const Error& e) {
      failures.emplace(index, e);
      throw;
    }
    remember(index, data);
    return data;
  }

  void remember(std::size_t index, const detail::BlockData& data) {
    ++stats.blocks_decoded;
    // The hints count against the cache's budget: a block the cache lets go
    // is let go here too, else one block per level and stream stays held.
    for (const std::size_t evicted : cache.insert(index, data))
      for (auto& per_stream : hint)
        for (Hint& h : per_stream)
          if (h.block == evicted) h = Hint{};
  }

  // Fetch planning (fetch_plan.cpp). The block of `stream` holding
  // `element`, or SIZE_MAX.
  std::size_t block_of(std::uint8_t stream, std::uint64_t element) const {
    const auto& list = stream_blocks[stream];
    auto it = std::upper_bound(list.begin(), list.end(), element,
                               [&](std::uint64_t e, std::size_t b) { return e < info.blocks[b].first_element; });
    if (it == list.begin()) return SIZE_MAX;
    const BlockInfo& b = info.blocks[*(it - 1)];
    return element - b.first_element < b.element_count ? *(it - 1) : SIZE_MAX;
  }
  // Reads the blocks not yet held in few requests (ByteSource::prefetch),
  // decodes them on several threads and puts them in the cache, as many as
  // its budget holds; a block that fails is remembered as failed, for the
  // walk to meet.
  void load_blocks(std::vector<std::size_t> blocks);
  void load_chunk(const std::vector<std::size_t>& blocks);
  // Loads the blocks a read of `box` at level of detail `lod` touches: for
  // a grid from the geometry, for an octree a level at a time (the node
  // words of one level name the blocks of the next).
  void plan_box(const Box& box, unsigned lod);

  // Pointer to element `element` of `stream` in a decoded block, which stays
  // alive until the next call.
  const std::uint8_t* element(std::uint8_t stream, std::uint64_t element) {
    const Hint& last = hint[stream][last_level[stream]];
    if (last.data && element - last.first < last.count)
      return last.data->data() + (element - last.first) * width_[stream];
    return element_elsewhere(stream, element);
  }

  // element() outside the block of the last lookup: out of line, so that
  // element() itself inlines into a walk's every step.
  [[gnu::noinline]] const std::uint8_t* element_elsewhere(std::uint8_t stream, std::uint64_t element) {
    const std::size_t width = width_[stream];
    for (std::size_t l = 0; l < hint[stream].size(); ++l) {
      const Hint& h = hint[stream][l];
      if (h.data && element - h.first < h.count) {
        last_level[stream] = l;
        return h.data->data() + (element - h.first) * width;
      }
    }
    const auto& list = stream_blocks[stream];
    auto it = std::upper_bound(list.begin(), list.end(), element,
                               [&](std::uint64_t e, std::size_t b) { return e < info.blocks[b].first_element; });
    if (it == list.begin() || element - info.blocks[*(it - 1)].first_element >= info.blocks[*(it - 1)].element_count)
      missing(stream,
              it == list.begin() ? 0 : info.blocks[*(it - 1)].first_element + info.blocks[*(it - 1)].element_count,
              it == list.end() ? nullptr : &info.blocks[*it]);
    const std::size_t found = *(it - 1);
    const BlockInfo& blk = info.blocks[found];
    Hint& h = hint[stream][blk.level];
    h = Hint{found, blk.first_element, blk.element_count, block(found)};
    last_level[stream] = blk.level;
    return h.data->data() + (element - blk.first_element) * width;
  }

  // An element in no block: only a salvaged file has such gaps (a sound index
  // covers every stream). One message per gap, so that a salvaging read lists
  // each gap once.
  [[noreturn]] void missing(std::uint8_t stream, std::uint64_t from, const BlockInfo* next) const {
    throw missing_error(stream, from, next);
  }
  Error missing_error(std::uint8_t stream, std::uint64_t from, const BlockInfo* next) const {
    return Error(info.salvage ? ErrorClass::Truncated : ErrorClass::Malformed,
                 file.path() + ": " +
                     (stream >= kStoredLevelSlot ? "stored level " + std::to_string(stream - kStoredLevelSlot)
                                                 : std::string(stream_name(stream))) +
                     " elements " + std::to_string(from) + " .. " +
                     (next ? std::to_string(next->first_element) : std::string("the end")) +
                     (info.salvage ? " were not found" : " are in no block"));
  }

  // The error of the block holding `element` of `stream` if that block
  // already failed, or of the gap in a salvaged index that holds it, found
  // without throwing: a salvaging walk meets a damaged block or a gap at
  // every voxel it holds, and an exception each time cost more than the rest
  // of the read (a cut 256^3 octree: 33 s, nearly all of it unwinding).
  const Error* known_failure(std::uint8_t stream, std::uint64_t element) const {
    if (failures.empty() && !info.salvage) return nullptr;
    const Hint& last = hint[stream][last_level[stream]];
    if (last.data && element - last.first < last.count) return nullptr;
    const auto& list = stream_blocks[stream];
    auto it = std::upper_bound(list.begin(), list.end(), element,
                               [&](std::uint64_t e, std::size_t b) { return e < info.blocks[b].first_element; });
    if (it == list.begin() || element - info.blocks[*(it - 1)].first_element >= info.blocks[*(it - 1)].element_count) {
      const std::uint64_t from =
          it == list.begin() ? 0 : info.blocks[*(it - 1)].first_element + info.blocks[*(it - 1)].element_count;
      const auto key = std::make_pair(stream, from);
      auto gap = gaps.find(key);
      if (gap == gaps.end())
        gap = gaps.emplace(key, missing_error(stream, from, it == list.end() ? nullptr : &info.blocks[*it])).first;
      return &gap->second;
    }
    const auto failed = failures.find(*(it - 1));
    return failed == failures.end() ? nullptr : &failed->second;
  }

  // Like element(), and *available = how many elements from `element` on
  // lie in the same decoded block, consecutive.
  const std::uint8_t* elements(std::uint8_t stream, std::uint64_t element, std::uint64_t* available) {
    const std::uint8_t* p = this->element(stream, element);
    const Hint& h = hint[stream][last_level[stream]];
    *available = h.first + h.count - element;
    return p;
  }

  std::uint64_t node_word(std::uint64_t index) { return layout::load<std::uint64_t>(element(2, index)); }

  // `count` elements of `stream` from `index` on where one decoded block
  // holds them all, else null; valid until the next lookup (tree_walk.hpp).
  const std::uint8_t* run(std::uint8_t stream, std::uint64_t index, std::uint64_t count) {
    std::uint64_t available = 0;
    const std::uint8_t* p = elements(stream, index, &available);
    return available < count ? nullptr : p;
  }

  // The eight values from `index` on (the children of one node), from one
  // decoded block where they lie in one, else one by one.
  void values8(std::uint64_t index, std::uint32_t* bits) {
    std::uint64_t available = 0;
    const std::uint8_t* p = elements(3, index, &available);
    if (available < 8) {
      for (unsigned c = 0; c < 8; ++c) bits[c] = value_bits(index + c);
      return;
    }
    if (width_[3] == 4)
      for (unsigned c = 0; c < 8; ++c) bits[c] = layout::load<std::uint32_t>(p + 4 * c);
    else
      for (unsigned c = 0; c < 8; ++c) bits[c] = layout::load<std::uint16_t>(p + 2 * c);
  }

  // Whether the file stores level of detail `lod` (a bricked grid, §8A.5).
  bool stored_level(unsigned lod) const {
    return lod >= 1 && lod < kSlots - kStoredLevelSlot && !stream_blocks[kStoredLevelSlot + lod].empty();
  }

  std::uint32_t value_bits(std::uint64_t index) {
    const std::uint8_t* p = element(3, index);
    if (width_[3] == 4) return layout::load<std::uint32_t>(p);
    return layout::load<std::uint16_t>(p);
  }

  void check_box(const Box& box, unsigned lod) const {
    if (lod > info.layout.depth)
      throw Error(ErrorClass::InvalidArgument, file.path() + ": level of detail " + std::to_string(lod) +
                                                   " exceeds the depth " + std::to_string(info.layout.depth));
    const Dims d = lod_dims(info.layout.dims, lod);
    for (int a = 0; a < 3; ++a)
      if (box.hi[a] > d[a] || box.lo[a] >= box.hi[a])
        throw Error(ErrorClass::InvalidArgument, file.path() + ": box " + box.to_string() +
                                                     " is empty or outside the volume at level of detail " +
                                                     std::to_string(lod));
    // A valid file may be 2^31 voxels a side: Box::voxel_count (64 bits)
    // would wrap, and an output sized by it would be overrun.
    __extension__ typedef unsigned __int128 u128;
    const u128 voxels = u128{box.hi[0] - box.lo[0]} * (box.hi[1] - box.lo[1]) * (box.hi[2] - box.lo[2]);
    if (voxels > (u128{1} << 62))
      throw Error(ErrorClass::InvalidArgument,
                  file.path() + ": box " + box.to_string() + " holds more than 2^62 voxels, too many for one read");
  }
};

namespace detail {

struct ImplAccess {
  Reader::Impl* impl;
  std::uint64_t node_word(std::uint64_t i) const { return impl->node_word(i); }
  std::uint32_t value_bits(std::uint64_t i) const { return impl->value_bits(i); }
  void values8(std::uint64_t i, std::uint32_t* bits) const { impl->values8(i, bits); }
  const std::uint8_t* run(std::uint8_t stream, std::uint64_t i, std::uint64_t count) const {
    return impl->run(stream, i, count);
  }
  std::size_t value_width() const { return impl->width_[3]; }
  const Error* known_failure(std::uint8_t stream, std::uint64_t i) const { return impl->known_failure(stream, i); }
};

}  // namespace detail
}  // namespace ivol
