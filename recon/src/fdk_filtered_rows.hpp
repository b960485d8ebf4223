// Filtered detector rows kept for the life of a reconstructor, so that each
// row of each view goes through the ramp filter once however thin the slabs
// that read it (issue 23): a slab's band of rows overlaps its neighbours',
// and at 4-slice slabs re-filtering them took 5.9× the filter's time.
//
// Rows are kept in pairs (2p, 2p + 1), the unit the filter kernel
// transforms together: a row filtered in any band has the same bits, since
// bands start on even rows. A pair's rows of every view lie together, in
// host memory while the budget lasts, then in a temporary file (unlinked at
// once, so it never outlives the process) in the directory given.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "fdk_plan.hpp"

namespace ivol::recon::detail {

class FdkDevice;

class FilteredRows {
 public:
  FilteredRows(std::size_t views, int rows, int columns, std::uint64_t host_budget, std::string temp_directory);
  ~FilteredRows();
  FilteredRows(const FilteredRows&) = delete;
  FilteredRows& operator=(const FilteredRows&) = delete;

  // Filters on `device` (configured for bands of `max_band_rows`) the row
  // pairs of `band` not kept yet, and keeps them. Returns detector rows
  // filtered, summed over views. One filtering at a time; load() of other
  // pairs may run meanwhile.
  std::uint64_t ensure(FdkDevice& device, const RowBand& band, int max_band_rows);
  // Forgets the pairs wholly below row `row` (rising) or at or above it
  // (not rising): slabs to come will not read them.
  void release_beyond(int row, bool rising);
  // Rows `band` (kept) of views [first_view, first_view + count) into the
  // filter's output layout: view v's row r at
  // out[(v·stride_rows + r − band.first + border)·stride_cols + border].
  void load(std::size_t first_view, int count, const RowBand& band, float* out, int stride_cols, int stride_rows) const;

  std::uint64_t peak_host_bytes() const { return peak_host_bytes_; }
  std::uint64_t peak_disk_bytes() const { return peak_disk_slots_ * pair_bytes(); }

 private:
  static constexpr std::int64_t kMissing = INT64_MIN;
  std::uint64_t pair_floats() const { return std::uint64_t{views_} * 2 * static_cast<std::uint64_t>(columns_); }
  std::uint64_t pair_bytes() const { return pair_floats() * sizeof(float); }
  bool has_pair(int pair) const { return where_[static_cast<std::size_t>(pair)] != kMissing; }
  void reserve(int pair);
  void forget(int pair);
  void open_file();
  void store(std::size_t first_view, int count, const RowBand& band, const float* images);
  std::uint64_t file_offset(int pair, std::size_t view) const;

  std::size_t views_;
  int columns_;
  std::uint64_t host_budget_;
  std::string temp_directory_;
  std::mutex mutex_;  // ensure() and release_beyond()
  // Per pair: 0 in host_, < 0 and not kMissing: −1 − its slot in the file.
  std::vector<std::int64_t> where_;
  std::vector<std::unique_ptr<float[]>> host_;  // per pair
  std::vector<std::uint64_t> free_slots_;
  std::uint64_t host_bytes_ = 0, peak_host_bytes_ = 0;
  std::uint64_t disk_slots_ = 0, used_slots_ = 0, peak_disk_slots_ = 0;
  std::vector<float> images_;  // ensure()'s filtered batch
  int fd_ = -1;
};

// Releases the filtered rows that no later slab of a reconstruction reads:
// bands move one way along the detector as slabs go up in z (each view's
// row is monotonic in z), so once every slab before one is done, the rows
// behind that slab's and all later bands go. The last slab's band stays for
// a later call (the CLI's writer slabs call reconstruct() in z order).
class RowRelease {
 public:
  // `bands`: this process's slabs' bands in slab order (empty ones allowed).
  RowRelease(FilteredRows* rows, const std::vector<RowBand>& bands);
  // Slab at `position` in `bands` is backprojected. Thread-safe.
  void done(std::size_t position);

 private:
  FilteredRows* rows_;
  bool rising_ = true;
  std::vector<int> edge_from_;  // per position: the lowest first (rising) or highest end of later bands
  std::vector<char> done_;
  std::size_t first_pending_ = 0;
  std::mutex mutex_;
};

// Rows × views the ramp filter works on for `bands` without a cache (each
// slab filters its own band), for reports that compare the two.
std::uint64_t rows_filtered_per_slab(const std::vector<RowBand>& bands, std::size_t views);

// A quarter of the physical memory: the default budget of the filtered rows.
std::uint64_t default_filtered_rows_budget();

}  // namespace ivol::recon::detail
