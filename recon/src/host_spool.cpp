#include "host_spool.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

namespace ivol::recon::detail {

RecordSpool::RecordSpool(std::size_t record_floats, HostAllowance& allowance, std::string directory, std::string what)
    : floats_(record_floats), allowance_(allowance), directory_(std::move(directory)), what_(std::move(what)) {
  if (directory_.empty()) {
    const char* tmpdir = std::getenv("TMPDIR");
    directory_ = tmpdir != nullptr && *tmpdir != '\0' ? tmpdir : "/tmp";
  }
}

RecordSpool::~RecordSpool() { release(); }

void RecordSpool::release() {
  allowance_.held -= held_bytes();
  std::vector<std::vector<float>>().swap(held_);
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

// Records are held from the first on while the allowance lasts; once one
// goes to the file, every later one does, so the file's records are
// contiguous from its start.
void RecordSpool::put(std::size_t record, const float* values) {
  count_ = std::max(count_, record + 1);
  if (record < held_.size()) {
    std::copy(values, values + floats_, held_[record].begin());
    return;
  }
  if (record == held_.size() && spilled_ == 0 && allowance_.held + bytes() <= allowance_.limit) {
    held_.emplace_back(values, values + floats_);
    allowance_.held += bytes();
    return;
  }
  if (fd_ < 0) open_file();
  transfer(true, record, const_cast<float*>(values));
  spilled_ += bytes();
}

void RecordSpool::get(std::size_t record, float* values) {
  if (record < held_.size()) {
    std::copy(held_[record].begin(), held_[record].end(), values);
    return;
  }
  transfer(false, record, values);
}

void RecordSpool::open_file() {
  fd_ = ::open(directory_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd_ >= 0) return;
  std::string name = directory_ + "/ivol-preview-XXXXXX";
  fd_ = ::mkstemp(name.data());
  if (fd_ < 0)
    throw std::runtime_error(what_ + " exceed the preview's memory budget of " + std::to_string(allowance_.limit) +
                             " bytes and no temporary file can be made in '" + directory_ +
                             "': " + std::strerror(errno));
  ::unlink(name.c_str());
}

void RecordSpool::transfer(bool write, std::size_t record, float* values) {
  auto* at = reinterpret_cast<char*>(values);
  std::uint64_t left = bytes();
  auto offset = static_cast<off_t>((record - held_.size()) * bytes());
  while (left > 0) {
    const ssize_t n = write ? ::pwrite(fd_, at, left, offset) : ::pread(fd_, at, left, offset);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw std::runtime_error(what_ + ": " + std::string(write ? "writing" : "reading") + " the temporary file in '" +
                               directory_ + "' failed: " + (n < 0 ? std::strerror(errno) : "end of file"));
    at += n, left -= static_cast<std::uint64_t>(n), offset += n;
  }
}

}  // namespace ivol::recon::detail
