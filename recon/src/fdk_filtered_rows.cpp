#include "fdk_filtered_rows.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "fdk_device.hpp"

namespace ivol::recon::detail {
namespace {

constexpr int kBorder = IVOL_BAND_BORDER_BEFORE;

std::string system_error(const std::string& what) { return what + ": " + std::strerror(errno); }

void write_all(int fd, const void* data, std::size_t bytes, std::uint64_t offset, const std::string& where) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw std::runtime_error(system_error("FDK: writing filtered rows to a temporary file in " + where));
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
    if (n <= 0) throw std::runtime_error(system_error("FDK: reading filtered rows from a temporary file in " + where));
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
      rows_(rows),
      columns_(columns),
      host_budget_(host_budget),
      temp_directory_(std::move(temp_directory)),
      where_(static_cast<std::size_t>((rows + 1) / 2), kMissing) {
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
    throw std::runtime_error(system_error("FDK: the filtered rows exceed their memory budget of " +
                                          std::to_string(host_budget_) +
                                          " bytes and no temporary file can be made in '" + temp_directory_ + "'"));
  ::unlink(name.c_str());
}

void FilteredRows::reserve(int pair) {
  std::int64_t& where = where_.at(static_cast<std::size_t>(pair));
  if (where != kMissing) return;
  if (host_bytes_ + pair_bytes() <= host_budget_) {
    where = static_cast<std::int64_t>(host_.size());
    host_.push_back(std::make_unique<float[]>(pair_floats()));
    host_bytes_ += pair_bytes();
    return;
  }
  if (fd_ < 0) open_file();
  where = -1 - static_cast<std::int64_t>(disk_slots_++);
}

float* FilteredRows::host_rows(int pair, std::size_t view) const {
  return host_[static_cast<std::size_t>(where_[static_cast<std::size_t>(pair)])].get() +
         view * 2 * static_cast<std::size_t>(columns_);
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
    const int pair = row / 2;
    if (!has_pair(pair)) throw std::logic_error("FDK: filtered row pair " + std::to_string(pair) + " not reserved");
    const int pair_rows = std::min(2, band.end - row);
    const bool on_disk = where_[static_cast<std::size_t>(pair)] < 0;
    if (on_disk) staging.assign(static_cast<std::size_t>(count) * 2 * columns, 0.0F);
    for (int v = 0; v < count; ++v) {
      float* to = on_disk ? staging.data() + static_cast<std::size_t>(v) * 2 * columns
                          : host_rows(pair, first_view + static_cast<std::size_t>(v));
      const float* from =
          images + static_cast<std::size_t>(v) * image + static_cast<std::size_t>(row - band.first) * columns;
      std::memcpy(to, from, static_cast<std::size_t>(pair_rows) * columns * sizeof(float));
    }
    if (on_disk)
      write_all(fd_, staging.data(), staging.size() * sizeof(float), file_offset(pair, first_view), temp_directory_);
  }
}

void FilteredRows::load(std::size_t first_view, int count, const RowBand& band, float* out, int stride_cols,
                        int stride_rows) const {
  const auto columns = static_cast<std::size_t>(columns_);
  std::vector<float> staging;
  for (int row = band.first; row < band.end; row += 2) {
    const int pair = row / 2;
    if (!has_pair(pair)) throw std::logic_error("FDK: filtered row pair " + std::to_string(pair) + " missing");
    const int pair_rows = std::min(2, band.end - row);
    const bool on_disk = where_[static_cast<std::size_t>(pair)] < 0;
    if (on_disk) {
      staging.resize(static_cast<std::size_t>(count) * 2 * columns);
      read_all(fd_, staging.data(), staging.size() * sizeof(float), file_offset(pair, first_view), temp_directory_);
    }
    for (int v = 0; v < count; ++v) {
      const float* from = on_disk ? staging.data() + static_cast<std::size_t>(v) * 2 * columns
                                  : host_rows(pair, first_view + static_cast<std::size_t>(v));
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

std::uint64_t rows_filtered_per_slab(const std::vector<RowBand>& bands, std::size_t views) {
  std::uint64_t rows = 0;
  for (const RowBand& b : bands) rows += static_cast<std::uint64_t>(b.rows());
  return rows * views;
}

std::uint64_t fill_filtered_rows(FilteredRows& rows, const std::vector<FdkDevice*>& devices,
                                 const std::vector<RowBand>& bands, int max_band_rows) {
  // The missing pairs, as runs of consecutive ones cut into chunks that fit
  // the devices' band buffers (an even number of rows, so pairs stay whole).
  int last_row = 0;
  for (const RowBand& b : bands) last_row = std::max(last_row, b.end);
  std::vector<char> wanted(static_cast<std::size_t>((last_row + 1) / 2), 0);
  std::vector<int> pair_end(wanted.size(), 0);  // the band's last row within the pair
  for (const RowBand& b : bands)
    for (int row = b.first; row < b.end; row += 2) {
      wanted[static_cast<std::size_t>(row / 2)] = 1;
      pair_end[static_cast<std::size_t>(row / 2)] =
          std::max(pair_end[static_cast<std::size_t>(row / 2)], std::min(b.end, row + 2));
    }
  const int chunk_rows = std::max(2, max_band_rows & ~1);
  std::vector<RowBand> chunks;
  for (std::size_t p = 0; p < wanted.size(); ++p) {
    if (!wanted[p] || rows.has_pair(static_cast<int>(p))) continue;
    RowBand& open =
        chunks.empty() || chunks.back().end != static_cast<int>(2 * p) || chunks.back().rows() + 2 > chunk_rows
            ? chunks.emplace_back(RowBand{static_cast<int>(2 * p), static_cast<int>(2 * p)})
            : chunks.back();
    open.end = pair_end[p];
    rows.reserve(static_cast<int>(p));
  }
  std::uint64_t filtered = 0;
  for (const RowBand& c : chunks) filtered += static_cast<std::uint64_t>(c.rows()) * rows.views();
  if (chunks.empty()) return 0;

  // Work items: (chunk, batch of views), taken in turn by every device.
  const std::size_t batches = (rows.views() + IVOL_BACKPROJECT_BATCH - 1) / IVOL_BACKPROJECT_BATCH;
  const std::size_t items = chunks.size() * batches;
  std::atomic<std::size_t> next{0};
  std::mutex failure_mutex;
  std::exception_ptr failure;
  std::atomic<bool> failed{false};
  auto work = [&](FdkDevice& device) {
    try {
      std::vector<float> images;
      for (std::size_t n = next++; n < items && !failed; n = next++) {
        const RowBand& chunk = chunks[n / batches];
        const std::size_t first_view = (n % batches) * IVOL_BACKPROJECT_BATCH;
        const int count = static_cast<int>(std::min<std::size_t>(IVOL_BACKPROJECT_BATCH, rows.views() - first_view));
        device.filter_to_host(first_view, count, chunk, images);
        rows.store(first_view, count, chunk, images.data());
      }
    } catch (const cl::Error& error) {
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure)
        failure =
            std::make_exception_ptr(std::runtime_error("FDK filtering on " + device.name() + ": " + describe(error)));
      failed = true;
    } catch (...) {
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> workers;
  for (std::size_t d = 1; d < devices.size(); ++d) workers.emplace_back(work, std::ref(*devices[d]));
  work(*devices[0]);
  for (std::thread& t : workers) t.join();
  if (failure) {
    for (const RowBand& c : chunks)
      for (int row = c.first; row < c.end; row += 2) rows.forget(row / 2);
    std::rethrow_exception(failure);
  }
  return filtered;
}

}  // namespace ivol::recon::detail
