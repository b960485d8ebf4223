#include "host_spool.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "ivol/error.hpp"

namespace ivol::recon::detail {

namespace {

// zstd's fastest level: the records are written once and read once, and a
// preview's noise in air gains little from more effort.
constexpr int kSpoolZstdLevel = 1;

// Elements of E bytes to E planes of bytes and back; E a constant, so that
// the compiler unrolls the inner loop.
template <std::size_t E>
void split_planes(const char* in, char* planes, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < E; ++b) planes[b * n + i] = in[i * E + b];
}
template <std::size_t E>
void join_planes(const char* planes, char* out, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < E; ++b) out[i * E + b] = planes[b * n + i];
}
void split_planes(const char* in, char* planes, std::size_t n, std::size_t element) {
  if (element == 2) return split_planes<2>(in, planes, n);
  if (element == 4) return split_planes<4>(in, planes, n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < element; ++b) planes[b * n + i] = in[i * element + b];
}
void join_planes(const char* planes, char* out, std::size_t n, std::size_t element) {
  if (element == 2) return join_planes<2>(planes, out, n);
  if (element == 4) return join_planes<4>(planes, out, n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < element; ++b) out[i * element + b] = planes[b * n + i];
}

}  // namespace

RecordSpool::RecordSpool(std::size_t record_bytes, std::size_t element_bytes, HostAllowance& allowance,
                         std::string directory, std::string what)
    : bytes_(record_bytes),
      element_(std::max<std::size_t>(element_bytes, 1)),
      allowance_(allowance),
      directory_(std::move(directory)),
      what_(std::move(what)) {
  if (bytes_ % element_ != 0) throw std::logic_error(what_ + ": a record is not a whole number of elements");
  if (directory_.empty()) {
    const char* tmpdir = std::getenv("TMPDIR");
    directory_ = tmpdir != nullptr && *tmpdir != '\0' ? tmpdir : "/tmp";
  }
}

RecordSpool::~RecordSpool() { release(); }

void RecordSpool::release() {
  allowance_.held -= held_bytes();
  std::vector<std::vector<char>>().swap(held_);
  std::vector<Stored>().swap(stored_);
  std::vector<char>().swap(planes_);
  std::vector<char>().swap(packed_);
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

// Records are held from the first on while the allowance lasts; once one
// goes to the file, every later one does, so the file's records follow the
// held ones without a gap.
void RecordSpool::put(std::size_t record, const void* bytes) {
  const auto* in = static_cast<const char*>(bytes);
  if (record < held_.size()) {
    std::copy(in, in + bytes_, held_[record].begin());
    return;
  }
  if (record != held_.size() + stored_.size())
    throw std::logic_error(what_ + ": record " + std::to_string(record) + " put out of order");
  count_ = record + 1;
  if (stored_.empty() && allowance_.held + bytes_ <= allowance_.limit) {
    held_.emplace_back(in, in + bytes_);
    allowance_.held += bytes_;
    return;
  }
  if (fd_ < 0) open_file();
  // Byte planes: the high bytes of nearby values (sign, exponent) repeat
  // where the low ones do not, and zstd finds the repeats once they are
  // side by side.
  planes_.resize(bytes_);
  split_planes(in, planes_.data(), bytes_ / element_, element_);
  packed_.resize(ZSTD_compressBound(bytes_));
  const std::size_t packed = ZSTD_compress(packed_.data(), packed_.size(), planes_.data(), bytes_, kSpoolZstdLevel);
  Stored stored{spilled_, static_cast<std::uint32_t>(bytes_)};
  const char* out = in;
  if (!ZSTD_isError(packed) && packed < bytes_) {
    stored.size = static_cast<std::uint32_t>(packed);
    out = packed_.data();
  }
  transfer(true, stored.offset, const_cast<char*>(out), stored.size);
  stored_.push_back(stored);
  spilled_ += stored.size;
}

void RecordSpool::get(std::size_t record, void* bytes) {
  auto* out = static_cast<char*>(bytes);
  if (record < held_.size()) {
    std::copy(held_[record].begin(), held_[record].end(), out);
    return;
  }
  if (record - held_.size() >= stored_.size())
    throw std::logic_error(what_ + ": record " + std::to_string(record) + " was never put");
  const Stored& stored = stored_[record - held_.size()];
  if (stored.size == bytes_) {
    transfer(false, stored.offset, out, bytes_);
    return;
  }
  packed_.resize(stored.size);
  transfer(false, stored.offset, packed_.data(), stored.size);
  planes_.resize(bytes_);
  const std::size_t got = ZSTD_decompress(planes_.data(), bytes_, packed_.data(), stored.size);
  if (ZSTD_isError(got) || got != bytes_)
    throw Error(ErrorClass::Io, what_ + ": a record read back from the temporary file in '" + directory_ +
                                    "' does not decompress to its size");
  join_planes(planes_.data(), out, bytes_ / element_, element_);
}

void RecordSpool::open_file() {
  fd_ = ::open(directory_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd_ >= 0) return;
  std::string name = directory_ + "/ivol-preview-XXXXXX";
  fd_ = ::mkstemp(name.data());
  if (fd_ < 0)
    throw Error(ErrorClass::Io, what_ + " exceed the preview's memory budget of " + std::to_string(allowance_.limit) +
                                    " bytes and no temporary file can be made in '" + directory_ +
                                    "': " + std::strerror(errno));
  ::unlink(name.c_str());
}

void RecordSpool::transfer(bool write, std::uint64_t offset, char* at, std::uint64_t size) {
  auto where = static_cast<off_t>(offset);
  while (size > 0) {
    const ssize_t n = write ? ::pwrite(fd_, at, size, where) : ::pread(fd_, at, size, where);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw Error(ErrorClass::Io, what_ + ": " + std::string(write ? "writing" : "reading") +
                                      " the temporary file in '" + directory_ +
                                      "' failed: " + (n < 0 ? std::strerror(errno) : "end of file"));
    at += n, size -= static_cast<std::uint64_t>(n), where += n;
  }
}

}  // namespace ivol::recon::detail
