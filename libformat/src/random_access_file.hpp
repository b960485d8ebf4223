// The bytes of a .ivol file, read by range: a local file with pread, or a
// file on an HTTP(S) server with range requests (http_source.hpp), chosen by
// the path ("http://", "https://"). Counts the bytes read and the requests
// made. Internal to libformat.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ivol::detail {

// Where the bytes come from.
class ByteSource {
 public:
  virtual ~ByteSource() = default;
  virtual std::uint64_t size() const = 0;
  // Exactly `size` bytes at `offset` (inside the file).
  virtual void read(std::uint64_t offset, void* out, std::size_t size) = 0;
  // Round trips to the storage so far (a local file: reads), and the bytes
  // they brought (over HTTP whole pages, more than were asked for).
  virtual std::uint64_t requests() const = 0;
  virtual std::uint64_t bytes_fetched() const = 0;
  // The ranges (offset, size) a read is about to need: a remote source
  // fetches them in few requests. A local file does nothing.
  virtual void prefetch(const std::vector<std::pair<std::uint64_t, std::uint64_t>>& /*ranges*/) {}
  // Whether the server ignored ranges and the whole file came in one
  // response (held in memory; a remote source only).
  virtual bool fetched_whole() const { return false; }
};

// Whether `path` names a remote file: an HTTP(S) URL or an s3:// object.
bool is_remote(const std::string& path);

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
  std::uint64_t requests() const { return source_->requests(); }
  std::uint64_t bytes_fetched() const { return source_->bytes_fetched(); }
  bool fetched_whole() const { return source_->fetched_whole(); }
  void prefetch(const std::vector<std::pair<std::uint64_t, std::uint64_t>>& ranges) { source_->prefetch(ranges); }
  std::uint64_t bytes_read = 0;

 private:
  std::string path_;
  std::unique_ptr<ByteSource> source_;
  std::uint64_t size_ = 0;
};

}  // namespace ivol::detail
