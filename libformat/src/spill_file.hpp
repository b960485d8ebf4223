// The streaming octree writer's temporary file: chunks of node words or
// values, each stored as zstd over its byte planes (the way the file's own
// blocks are compressed, so the spill stays near the output's size), in a
// file that has no name from its creation (O_TMPFILE) or loses it at once:
// nothing is left behind when the process ends, however it ends. Internal
// to libformat.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ivol::detail {

// A chunk ready to be appended: its bytes as stored and its size decoded.
struct PackedChunk {
  std::vector<std::uint8_t> stored;
  std::uint64_t raw_bytes = 0;
};

// Compresses `count` elements of `width` bytes; safe on several threads at
// once. A chunk that does not shrink is stored as it is (stored size equal
// to its raw size says so).
PackedChunk pack_chunk(const void* elements, std::uint64_t count, std::size_t width, int zstd_level);

class SpillFile {
 public:
  // An unnamed file in `directory`; throws ivol::Error naming the directory.
  explicit SpillFile(const std::string& directory);
  ~SpillFile();
  SpillFile(const SpillFile&) = delete;
  SpillFile& operator=(const SpillFile&) = delete;

  // Appends the stored bytes; returns where they start. One thread at a time.
  std::uint64_t append(const std::uint8_t* data, std::size_t size);
  // Reads `stored_bytes` at `at` and decodes them into `out`, which has room
  // for `count` elements of `width` bytes.
  void read_chunk(std::uint64_t at, std::uint64_t stored_bytes, void* out, std::uint64_t count,
                  std::size_t width) const;
  std::uint64_t size() const { return size_; }
  const std::string& directory() const { return directory_; }

 private:
  void read_raw(std::uint64_t at, void* out, std::size_t size) const;
  std::string directory_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

}  // namespace ivol::detail
