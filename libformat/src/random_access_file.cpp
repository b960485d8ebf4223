#include "random_access_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "ivol/error.hpp"

namespace ivol::detail {

RandomAccessFile::RandomAccessFile(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw Error(ErrorClass::Io, path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    throw Error(ErrorClass::Io, path + ": not a regular file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
}

RandomAccessFile::~RandomAccessFile() {
  if (fd_ >= 0) ::close(fd_);
}

void RandomAccessFile::read(std::uint64_t offset, void* out, std::size_t size) {
  auto* p = static_cast<unsigned char*>(out);
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
    size -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
    bytes_read += static_cast<std::uint64_t>(n);
  }
}

std::vector<std::uint8_t> RandomAccessFile::read(std::uint64_t offset, std::size_t size) {
  std::vector<std::uint8_t> out(size);
  read(offset, out.data(), size);
  return out;
}

}  // namespace ivol::detail
