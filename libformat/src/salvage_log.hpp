// The damage a salvaging walk met, as boxes (tree_walk.hpp's walk_box).
#pragma once

#include <algorithm>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "ivol/geometry.hpp"
#include "ivol/reader.hpp"

namespace ivol::detail {

// Where a salvaging walk met damage: the region it filled from a coarser
// level instead.
// Regions are merged per cause (the message names the damaged block or the
// missing run of elements) where their union is a box, so that a walk in
// Morton order lists a damaged block's region as a few boxes, not voxel by
// voxel; every listed box is exactly what was filled. At most kMaxEntries
// entries: the rest go into one last entry, the box around them.
struct SalvageLog {
  static constexpr std::size_t kMaxEntries = 1000;
  std::vector<DamagedRegion>& out;
  std::vector<DamagedRegion> entries = {};
  std::vector<bool> live = {};
  std::unordered_map<std::string, std::vector<std::size_t>> open = {};  // live entries of each cause
  std::size_t live_count = 0;
  std::size_t overflow = SIZE_MAX;

  static bool joins(const Box& a, const Box& b, Box& joined) {
    int differing = -1;
    for (int axis = 0; axis < 3; ++axis) {
      if (a.lo[axis] == b.lo[axis] && a.hi[axis] == b.hi[axis]) continue;
      if (differing >= 0) return false;
      if (a.hi[axis] != b.lo[axis] && b.hi[axis] != a.lo[axis]) return false;
      differing = axis;
    }
    joined = a;
    if (differing >= 0) {
      joined.lo[differing] = std::min(a.lo[differing], b.lo[differing]);
      joined.hi[differing] = std::max(a.hi[differing], b.hi[differing]);
    }
    return true;
  }

  void add(const Box& region, unsigned level, const std::string& message) {
    auto& mine = open[message];
    Box box = region;
    unsigned lowest = level;
    Box joined;
    while (!mine.empty() && joins(entries[mine.back()].region, box, joined)) {
      box = joined;
      lowest = std::min(lowest, entries[mine.back()].level);
      live[mine.back()] = false;
      --live_count;
      mine.pop_back();
    }
    if (live_count >= kMaxEntries) {
      if (overflow == SIZE_MAX) {
        overflow = entries.size();
        entries.push_back({box, lowest, "further damage, not listed one by one (the box around it)"});
        live.push_back(true);
        return;
      }
      DamagedRegion& r = entries[overflow];
      for (int a = 0; a < 3; ++a) {
        r.region.lo[a] = std::min(r.region.lo[a], box.lo[a]);
        r.region.hi[a] = std::max(r.region.hi[a], box.hi[a]);
      }
      r.level = std::min(r.level, lowest);
      return;
    }
    mine.push_back(entries.size());
    entries.push_back({box, lowest, message});
    live.push_back(true);
    ++live_count;
  }

  // Hands the entries to the caller's list, in the order they were met.
  void flush() {
    for (std::size_t i = 0; i < entries.size(); ++i)
      if (live[i]) out.push_back(std::move(entries[i]));
    entries.clear();
    live.clear();
    open.clear();
    live_count = 0;
    overflow = SIZE_MAX;
  }
  ~SalvageLog() { flush(); }
};

}  // namespace ivol::detail
