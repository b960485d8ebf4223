#include "fdk_filtered_rows.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "fdk_device.hpp"
#include "ivol/error.hpp"

namespace ivol::recon::detail {
namespace {

constexpr int kBorder = IVOL_BAND_BORDER_BEFORE;

std::string system_error(const std::string& what) { return what + ": " + std::strerror(errno); }

void write_all(int fd, const void* data, std::size_t bytes, std::uint64_t offset, const std::string& where) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(ErrorClass::Io, system_error("FDK: writing filtered rows to a temporary file in " + where));
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
  }
}

void read_all(int fd, void* data, std::size_t bytes, std::uint64_t offset, const std::string& where) {
  char* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw Error(ErrorClass::Io, system_error("FDK: reading filtered rows from a temporary file in " + where));
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
  }
}

}  // namespace

std::uint64_t default_filtered_rows_budget() {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return std::uint64_t{1} << 30;
  return static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page) / 4;
}

FilteredRows::FilteredRows(std::size_t views, int rows, int columns, std::uint64_t host_budget,
                           std::string temp_directory)
    : views_(views),
      columns_(columns),
      host_budget_(host_budget),
      temp_directory_(std::move(temp_directory)),
      where_(static_cast<std::size_t>((rows + 1) / 2), kMissing),
      host_(where_.size()) {
  if (temp_directory_.empty()) {
    const char* tmpdir = std::getenv("TMPDIR");
    temp_directory_ = tmpdir != nullptr && *tmpdir != '\0' ? tmpdir : "/tmp";
  }
}

FilteredRows::~FilteredRows() {
  if (fd_ >= 0) ::close(fd_);
}

void FilteredRows::open_file() {
  // O_TMPFILE: no name ever; else a named file unlinked at once.
  fd_ = ::open(temp_directory_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd_ >= 0) return;
  std::string name = temp_directory_ + "/ivol-filtered-rows-XXXXXX";
  fd_ = ::mkstemp(name.data());
  if (fd_ < 0)
    throw Error(ErrorClass::Io,
                system_error("FDK: the filtered rows exceed their memory budget of " + std::to_string(host_budget_) +
                             " bytes and no temporary file can be made in '" + temp_directory_ + "'"));
  ::unlink(name.c_str());
}

void FilteredRows::reserve(int pair) {
  std::int64_t& where = where_.at(static_cast<std::size_t>(pair));
  if (where != kMissing) return;
  if (host_bytes_ + pair_bytes() <= host_budget_) {
    host_[static_cast<std::size_t>(pair)] = std::make_unique<float[]>(pair_floats());
    where = 0;
    host_bytes_ += pair_bytes();
    peak_host_bytes_ = std::max(peak_host_bytes_, host_bytes_);
    return;
  }
  if (fd_ < 0) open_file();
  std::uint64_t slot = disk_slots_;
  if (!free_slots_.empty()) {
    slot = free_slots_.back();
    free_slots_.pop_back();
  } else {
    ++disk_slots_;
  }
  where = -1 - static_cast<std::int64_t>(slot);
  peak_disk_slots_ = std::max(peak_disk_slots_, ++used_slots_);
}

void FilteredRows::forget(int pair) {
  std::int64_t& where = where_[static_cast<std::size_t>(pair)];
  if (where == kMissing) return;
  if (where >= 0) {
    host_[static_cast<std::size_t>(pair)].reset();
    host_bytes_ -= pair_bytes();
  } else {
    const auto slot = static_cast<std::uint64_t>(-1 - where);
    // Give the disk back; the slot is reused by the next pair.
    ::fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, static_cast<off_t>(slot * pair_bytes()),
                static_cast<off_t>(pair_bytes()));
    free_slots_.push_back(slot);
    --used_slots_;
  }
  where = kMissing;
}

std::uint64_t FilteredRows::file_offset(int pair, std::size_t view) const {
  const auto slot = static_cast<std::uint64_t>(-1 - where_[static_cast<std::size_t>(pair)]);
  return slot * pair_bytes() + std::uint64_t{view} * 2 * static_cast<std::uint64_t>(columns_) * sizeof(float);
}

void FilteredRows::store(std::size_t first_view, int count, const RowBand& band, const float* images) {
  const auto columns = static_cast<std::size_t>(columns_);
  const std::size_t image = static_cast<std::size_t>(band.rows()) * columns;
  std::vector<float> staging;  // a file pair's rows of the batch's views, together
  for (int row = band.first; row < band.end; row += 2) {
    const auto pair = static_cast<std::size_t>(row / 2);
    const int pair_rows = std::min(2, band.end - row);
    const bool on_disk = where_[pair] < 0;
    if (on_disk) staging.assign(static_cast<std::size_t>(count) * 2 * columns, 0.0F);
    for (int v = 0; v < count; ++v) {
      float* to = on_disk ? staging.data() + static_cast<std::size_t>(v) * 2 * columns
                          : host_[pair].get() + (first_view + static_cast<std::size_t>(v)) * 2 * columns;
      const float* from =
          images + static_cast<std::size_t>(v) * image + static_cast<std::size_t>(row - band.first) * columns;
      std::memcpy(to, from, static_cast<std::size_t>(pair_rows) * columns * sizeof(float));
    }
    if (on_disk)
      write_all(fd_, staging.data(), staging.size() * sizeof(float), file_offset(row / 2, first_view), temp_directory_);
  }
}

void FilteredRows::load(std::size_t first_view, int count, const RowBand& band, float* out, int stride_cols,
                        int stride_rows) const {
  const auto columns = static_cast<std::size_t>(columns_);
  std::vector<float> staging;
  for (int row = band.first; row < band.end; row += 2) {
    const auto pair = static_cast<std::size_t>(row / 2);
    if (!has_pair(row / 2)) throw std::logic_error("FDK: filtered row pair " + std::to_string(pair) + " missing");
    const int pair_rows = std::min(2, band.end - row);
    const bool on_disk = where_[pair] < 0;
    if (on_disk) {
      staging.resize(static_cast<std::size_t>(count) * 2 * columns);
      read_all(fd_, staging.data(), staging.size() * sizeof(float), file_offset(row / 2, first_view), temp_directory_);
    }
    for (int v = 0; v < count; ++v) {
      const float* from = on_disk ? staging.data() + static_cast<std::size_t>(v) * 2 * columns
                                  : host_[pair].get() + (first_view + static_cast<std::size_t>(v)) * 2 * columns;
      for (int r = 0; r < pair_rows; ++r) {
        float* to = out +
                    (static_cast<std::size_t>(v) * static_cast<std::size_t>(stride_rows) +
                     static_cast<std::size_t>(row - band.first + r + kBorder)) *
                        static_cast<std::size_t>(stride_cols) +
                    kBorder;
        std::memcpy(to, from + static_cast<std::size_t>(r) * columns, columns * sizeof(float));
      }
    }
  }
}

std::uint64_t FilteredRows::ensure(FdkDevice& device, const RowBand& band, int max_band_rows) {
  if (band.rows() == 0) return 0;
  std::lock_guard<std::mutex> lock(mutex_);
  // The missing pairs, as runs of consecutive ones cut into chunks that fit
  // the device's band buffers (an even number of rows, so pairs stay whole).
  const int chunk_rows = std::max(2, max_band_rows & ~1);
  std::vector<RowBand> chunks;
  for (int row = band.first; row < band.end; row += 2) {
    if (has_pair(row / 2)) continue;
    const bool extend = !chunks.empty() && chunks.back().end == row && chunks.back().rows() + 2 <= chunk_rows;
    if (!extend) chunks.push_back(RowBand{row, row});
    chunks.back().end = std::min(band.end, row + 2);
  }
  std::uint64_t filtered = 0;
  for (const RowBand& chunk : chunks) {
    for (int row = chunk.first; row < chunk.end; row += 2) reserve(row / 2);
    try {
      for (std::size_t first = 0; first < views_; first += IVOL_BACKPROJECT_BATCH) {
        const int count = static_cast<int>(std::min<std::size_t>(IVOL_BACKPROJECT_BATCH, views_ - first));
        device.filter_to_host(first, count, chunk, images_);
        store(first, count, chunk, images_.data());
      }
    } catch (...) {
      for (int row = chunk.first; row < chunk.end; row += 2) forget(row / 2);
      throw;
    }
    filtered += static_cast<std::uint64_t>(chunk.rows()) * views_;
  }
  return filtered;
}

void FilteredRows::release_beyond(int row, bool rising) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int pairs = static_cast<int>(where_.size());
  if (rising)
    for (int pair = 0; pair < std::min(pairs, row / 2); ++pair) forget(pair);
  else
    for (int pair = std::max(0, (row + 1) / 2); pair < pairs; ++pair) forget(pair);
}

RowRelease::RowRelease(FilteredRows* rows, const std::vector<RowBand>& bands)
    : rows_(rows), edge_from_(bands.size()), done_(bands.size(), 0) {
  int first_band = -1;
  int last_band = -1;
  for (std::size_t p = 0; p < bands.size(); ++p)
    if (bands[p].rows() > 0) {
      if (first_band < 0) first_band = static_cast<int>(p);
      last_band = static_cast<int>(p);
    }
  if (first_band >= 0) rising_ = bands[first_band].first <= bands[last_band].first;
  // From the last slab back: the edge of every band from here on.
  int edge = rising_ ? INT_MAX : INT_MIN;
  for (std::size_t p = bands.size(); p-- > 0;) {
    if (bands[p].rows() > 0) edge = rising_ ? std::min(edge, bands[p].first) : std::max(edge, bands[p].end);
    edge_from_[p] = edge;
  }
}

void RowRelease::done(std::size_t position) {
  if (rows_ == nullptr || edge_from_.empty()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  done_[position] = 1;
  while (first_pending_ < done_.size() && done_[first_pending_]) ++first_pending_;
  // All done: the last band stays, for the next call's first slab.
  const std::size_t from = std::min(first_pending_, done_.size() - 1);
  const int edge = edge_from_[from];
  if (edge != INT_MAX && edge != INT_MIN) rows_->release_beyond(edge, rising_);
}

std::uint64_t rows_filtered_per_slab(const std::vector<RowBand>& bands, std::size_t views) {
  std::uint64_t rows = 0;
  for (const RowBand& b : bands) rows += static_cast<std::uint64_t>(b.rows());
  return rows * views;
}

}  // namespace ivol::recon::detail
