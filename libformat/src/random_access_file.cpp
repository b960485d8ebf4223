#include "random_access_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "http_source.hpp"
#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

class LocalFile final : public ByteSource {
 public:
  explicit LocalFile(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw Error(ErrorClass::Io, path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd_);
      throw Error(ErrorClass::Io, path + ": not a regular file");
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
  }
  ~LocalFile() override { ::close(fd_); }

  std::uint64_t size() const override { return size_; }
  std::uint64_t requests() const override { return requests_; }
  std::uint64_t bytes_fetched() const override { return fetched_; }

  void read(std::uint64_t offset, void* out, std::size_t size) override {
    auto* p = static_cast<unsigned char*>(out);
    ++requests_;
    while (size > 0) {
      const ssize_t n = ::pread(fd_, p, size, static_cast<off_t>(offset));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0)
        throw Error(ErrorClass::Io,
                    path_ + ": read failed at offset " + std::to_string(offset) + ": " + std::strerror(errno));
      if (n == 0)
        throw Error(ErrorClass::Truncated, path_ + ": the file ended at offset " + std::to_string(offset) +
                                               " while reading (did it change while open?)");
      p += n;
      fetched_ += static_cast<std::uint64_t>(n);
      size -= static_cast<std::size_t>(n);
      offset += static_cast<std::uint64_t>(n);
    }
  }

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::uint64_t requests_ = 0;
  std::uint64_t fetched_ = 0;
};

}  // namespace

bool is_remote(const std::string& path) {
  return path.rfind("http://", 0) == 0 || path.rfind("https://", 0) == 0 || path.rfind("s3://", 0) == 0;
}

RandomAccessFile::RandomAccessFile(const std::string& path) : path_(path) {
  if (is_remote(path))
    source_ = open_http_source(path);
  else
    source_ = std::make_unique<LocalFile>(path);
  size_ = source_->size();
}

RandomAccessFile::~RandomAccessFile() = default;

void RandomAccessFile::read(std::uint64_t offset, void* out, std::size_t size) {
  if (size == 0) return;
  source_->read(offset, out, size);
  bytes_read += size;
}

std::vector<std::uint8_t> RandomAccessFile::read(std::uint64_t offset, std::size_t size) {
  std::vector<std::uint8_t> out(size);
  read(offset, out.data(), size);
  return out;
}

}  // namespace ivol::detail
