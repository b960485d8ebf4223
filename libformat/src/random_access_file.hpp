// A file read with pread, counting the bytes read. Internal to libformat.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace ivol::detail {

class RandomAccessFile {
 public:
  explicit RandomAccessFile(const std::string& path);
  ~RandomAccessFile();
  RandomAccessFile(const RandomAccessFile&) = delete;
  RandomAccessFile& operator=(const RandomAccessFile&) = delete;

  const std::string& path() const { return path_; }
  std::uint64_t size() const { return size_; }
  // Reads exactly `size` bytes at `offset` (the caller checked the range).
  void read(std::uint64_t offset, void* out, std::size_t size);
  std::vector<std::uint8_t> read(std::uint64_t offset, std::size_t size);
  std::uint64_t bytes_read = 0;

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

}  // namespace ivol::detail
