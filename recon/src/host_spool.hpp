// Records kept until a later pass reads them back: in host memory while a
// budget shared by several spools lasts, the rest in an unlinked temporary
// file, each record there compressed (its bytes split into planes, then
// zstd) or stored as it is when that does not make it smaller (the detection
// preview's cell layers and its samples for Otsu's threshold, issue 23).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ivol::recon::detail {

// Bytes that the spools sharing it may hold in memory together.
struct HostAllowance {
  std::uint64_t limit = 0;
  std::uint64_t held = 0;
};

class RecordSpool {
 public:
  // A record is `record_bytes` bytes of elements `element_bytes` wide (the
  // planes the compression splits them into). `what` names the records in
  // errors ("the detection preview's cells").
  RecordSpool(std::size_t record_bytes, std::size_t element_bytes, HostAllowance& allowance, std::string directory,
              std::string what);
  RecordSpool(const RecordSpool&) = delete;
  RecordSpool& operator=(const RecordSpool&) = delete;
  ~RecordSpool();

  // Records are put in increasing order (0, 1, 2 ...), each once; a held one
  // may be put again.
  void put(std::size_t record, const void* bytes);
  void get(std::size_t record, void* bytes);
  // Gives the held records' memory back to the allowance and closes the file.
  void release();

  std::size_t record_bytes() const { return bytes_; }
  std::size_t count() const { return count_; }
  std::uint64_t held_bytes() const { return held_.size() * bytes_; }
  // What the temporary file holds: records as compressed, or as they are.
  std::uint64_t spilled_bytes() const { return spilled_; }
  // What the spilled records would take as they are.
  std::uint64_t spilled_raw_bytes() const { return stored_.size() * bytes_; }

 private:
  struct Stored {
    std::uint64_t offset = 0;
    std::uint32_t size = 0;  // == record_bytes: stored as it is
  };
  void open_file();
  void transfer(bool write, std::uint64_t offset, char* at, std::uint64_t size);

  std::size_t bytes_;
  std::size_t element_;
  HostAllowance& allowance_;
  std::string directory_;
  std::string what_;
  std::vector<std::vector<char>> held_;
  std::vector<Stored> stored_;  // the spilled records, from record held_.size() on
  std::vector<char> planes_, packed_;
  std::size_t count_ = 0;
  int fd_ = -1;
  std::uint64_t spilled_ = 0;
};

}  // namespace ivol::recon::detail
