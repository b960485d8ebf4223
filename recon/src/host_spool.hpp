// Records of floats kept until a later pass reads them back: in host memory
// while a budget shared by several spools lasts, the rest in an unlinked
// temporary file (the detection preview's cell layers and its samples for
// Otsu's threshold, issue 23).
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
  // `what` names the records in errors ("the detection preview's cells").
  RecordSpool(std::size_t record_floats, HostAllowance& allowance, std::string directory, std::string what);
  RecordSpool(const RecordSpool&) = delete;
  RecordSpool& operator=(const RecordSpool&) = delete;
  ~RecordSpool();

  // Records are put in increasing order (0, 1, 2 ...); a held one may be put again.
  void put(std::size_t record, const float* values);
  void get(std::size_t record, float* values);
  // Gives the held records' memory back to the allowance and closes the file.
  void release();

  std::size_t record_floats() const { return floats_; }
  std::size_t count() const { return count_; }
  std::uint64_t held_bytes() const { return held_.size() * bytes(); }
  std::uint64_t spilled_bytes() const { return spilled_; }

 private:
  std::uint64_t bytes() const { return floats_ * sizeof(float); }
  void open_file();
  void transfer(bool write, std::size_t record, float* values);

  std::size_t floats_;
  HostAllowance& allowance_;
  std::string directory_;
  std::string what_;
  std::vector<std::vector<float>> held_;
  std::size_t count_ = 0;
  int fd_ = -1;
  std::uint64_t spilled_ = 0;
};

}  // namespace ivol::recon::detail
