// The values of a structure in flight between a reconstruction and a writer.
#include <algorithm>
#include <stdexcept>

#include "ivol/structure_stream.hpp"

namespace ivol {

namespace {

constexpr std::uint64_t kPage = StructureValueWindow::kPageValues;
constexpr std::int64_t kTallEntryBytes = 40;  // a hash-map node and its bucket, about

std::uint32_t brick_end(const Brick& b, const Dims& dims) {
  return static_cast<std::uint32_t>(
      std::min<std::uint64_t>(dims[2], b.origin[2] + std::uint64_t{b.voxel[2]} * b.count[2]));
}

}  // namespace

StructureValueWindow::StructureValueWindow(const VoxelStructure& structure, bool keep_all)
    : structure_(structure), keep_all_(keep_all) {
  const std::uint64_t page_count = (structure.voxel_count() + kPage - 1) / kPage;
  pages_.resize(page_count);
  page_end_.assign(page_count, 0);
  released_.assign(page_count, 0);
  tall_by_end_.resize(std::uint64_t{structure.dims()[2]} + 1);
  // The last slice each page's values reach: a brick's values are z-major,
  // so the part of a brick in one page ends at the slice of its last value.
  const Dims& dims = structure.dims();
  for (std::uint32_t n = 0; n < structure.bricks().size(); ++n) {
    if (tall(n)) continue;
    const Brick& b = structure.bricks()[n];
    const std::uint64_t plane = std::uint64_t{b.count[0]} * b.count[1];
    const std::uint64_t end = b.first_value + b.voxel_count();
    for (std::uint64_t p = b.first_value / kPage; p * kPage < end; ++p) {
      const std::uint64_t last = std::min(end, (p + 1) * kPage) - 1;
      const std::uint64_t k = (last - b.first_value) / plane;
      const auto z_end = static_cast<std::uint32_t>(
          std::min<std::uint64_t>(dims[2], b.origin[2] + (k + 1) * std::uint64_t{b.voxel[2]}));
      page_end_[p] = std::max(page_end_[p], z_end);
    }
  }
}

StructureValueWindow::~StructureValueWindow() = default;

bool StructureValueWindow::tall(std::uint32_t brick) const {
  const Brick& b = structure_.bricks()[brick];
  return b.count[0] == 1 && b.count[1] == 1 && b.count[2] == 1 && b.voxel[2] > kTallVoxel;
}

void StructureValueWindow::note_held(std::int64_t bytes) {
  held_bytes_ = static_cast<std::uint64_t>(static_cast<std::int64_t>(held_bytes_) + bytes);
  peak_bytes_ = std::max(peak_bytes_, held_bytes_);
}

float& StructureValueWindow::at(std::uint32_t brick, std::uint64_t index) {
  if (tall(brick)) {
    auto [it, inserted] = tall_values_.try_emplace(index, 0.0F);
    if (inserted) {
      const std::uint32_t end = brick_end(structure_.bricks()[brick], structure_.dims());
      if (end <= released_below_ && !keep_all_)
        throw std::logic_error("structure values: voxel " + std::to_string(index) + " written after its release");
      tall_by_end_[end].push_back(index);
      note_held(kTallEntryBytes);
    }
    return it->second;
  }
  const std::uint64_t p = index / kPage;
  if (!pages_[p]) {
    if (released_[p])
      throw std::logic_error("structure values: voxel " + std::to_string(index) + " written after its release");
    pages_[p] = std::make_unique<float[]>(kPage);  // zeroed
    live_pages_.push_back(static_cast<std::uint32_t>(p));
    note_held(static_cast<std::int64_t>(kPage * sizeof(float)));
  }
  return pages_[p][index % kPage];
}

float StructureValueWindow::value(std::uint32_t brick, std::uint64_t index) const {
  if (tall(brick)) {
    const auto it = tall_values_.find(index);
    if (it != tall_values_.end()) return it->second;
    if (released_below_ >= brick_end(structure_.bricks()[brick], structure_.dims()))
      throw std::logic_error("structure values: voxel " + std::to_string(index) + " read after its release");
    return 0.0F;
  }
  const std::uint64_t p = index / kPage;
  if (pages_[p]) return pages_[p][index % kPage];
  if (released_[p])
    throw std::logic_error("structure values: voxel " + std::to_string(index) + " read after its release");
  return 0.0F;
}

void StructureValueWindow::release_below(std::uint32_t z) {
  if (keep_all_ || z <= released_below_) return;
  z = std::min<std::uint32_t>(z, structure_.dims()[2]);
  for (std::uint32_t end = released_below_; end <= z; ++end) {
    for (std::uint64_t index : tall_by_end_[end]) {
      tall_values_.erase(index);
      note_held(-kTallEntryBytes);
    }
    std::vector<std::uint64_t>().swap(tall_by_end_[end]);
  }
  released_below_ = z;
  for (std::size_t n = 0; n < live_pages_.size();) {
    const std::uint32_t p = live_pages_[n];
    if (page_end_[p] <= z) {
      pages_[p].reset();
      released_[p] = 1;
      note_held(-static_cast<std::int64_t>(kPage * sizeof(float)));
      live_pages_[n] = live_pages_.back();
      live_pages_.pop_back();
    } else {
      ++n;
    }
  }
}

}  // namespace ivol
