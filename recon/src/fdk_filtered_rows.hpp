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

  int columns() const { return columns_; }
  std::size_t views() const { return views_; }
  bool has_pair(int pair) const { return where_[static_cast<std::size_t>(pair)] != kMissing; }
  // Finds room for a pair: host memory within the budget, else the file.
  // From one thread, before any store() or load() of the pair.
  void reserve(int pair);
  // Marks a reserved pair missing again (its filtering failed); its room
  // is not reused.
  void forget(int pair) { where_.at(static_cast<std::size_t>(pair)) = kMissing; }
  // Rows [band.first, band.end) of views [first_view, first_view + count),
  // as `count` images of band.rows() × columns floats. The band's pairs are
  // reserved. Concurrent calls store different pairs or views.
  void store(std::size_t first_view, int count, const RowBand& band, const float* images);
  // The same rows into the filter's output layout: view v's row r at
  // out[(v·stride_rows + r − band.first + border)·stride_cols + border].
  // Concurrent calls are safe.
  void load(std::size_t first_view, int count, const RowBand& band, float* out, int stride_cols, int stride_rows) const;

  std::uint64_t host_bytes() const { return host_bytes_; }
  std::uint64_t disk_bytes() const { return disk_slots_ * pair_bytes(); }
  std::uint64_t host_budget() const { return host_budget_; }
  // The directory of the file, once there is one (for messages).
  const std::string& temp_directory() const { return temp_directory_; }

 private:
  static constexpr std::int64_t kMissing = INT64_MIN;
  std::uint64_t pair_floats() const { return std::uint64_t{views_} * 2 * static_cast<std::uint64_t>(columns_); }
  std::uint64_t pair_bytes() const { return pair_floats() * sizeof(float); }
  void open_file();
  // A pair's view `view`, rows 2p and 2p + 1, 2 × columns floats.
  float* host_rows(int pair, std::size_t view) const;
  std::uint64_t file_offset(int pair, std::size_t view) const;

  std::size_t views_;
  int rows_;
  int columns_;
  std::uint64_t host_budget_;
  std::string temp_directory_;
  // Per pair: ≥ 0, its index in host_; < 0 and not kMissing, −1 − its slot in the file.
  std::vector<std::int64_t> where_;
  std::vector<std::unique_ptr<float[]>> host_;
  std::uint64_t host_bytes_ = 0;
  std::uint64_t disk_slots_ = 0;
  int fd_ = -1;
};

// Filters, on every device at once, the row pairs of `bands` that `rows`
// lacks, each once, and stores them; the devices must be configured for
// bands of `max_band_rows`. Returns detector rows filtered, summed over views.
std::uint64_t fill_filtered_rows(FilteredRows& rows, const std::vector<FdkDevice*>& devices,
                                 const std::vector<RowBand>& bands, int max_band_rows);

// Rows × views the ramp filter works on for `bands` without a cache (each
// slab filters its own band), for reports that compare the two.
std::uint64_t rows_filtered_per_slab(const std::vector<RowBand>& bands, std::size_t views);

// A quarter of the physical memory: the default budget of the filtered rows.
std::uint64_t default_filtered_rows_budget();

}  // namespace ivol::recon::detail
