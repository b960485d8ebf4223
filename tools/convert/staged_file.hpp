// A file written under a temporary name in its final directory and renamed
// into place only when complete, so that a reader never sees a partial file
// and a failed write leaves nothing behind; a killed one leaves an unlocked
// temporary that the next write of the same file removes. For converters whose output goes
// through a foreign library (HDF5, OpenVDB) that opens files by name.
#pragma once

#include <string>

namespace ivol::convert {

class StagedFile {
 public:
  // Creates an empty, uniquely named temporary file next to final_path.
  explicit StagedFile(const std::string& final_path);
  // Removes the temporary file unless commit() succeeded.
  ~StagedFile();
  StagedFile(const StagedFile&) = delete;
  StagedFile& operator=(const StagedFile&) = delete;

  // Where the library should write.
  const std::string& temp_path() const { return temp_path_; }

  // Flushes the finished temporary file to disk and renames it to final_path.
  void commit();

 private:
  std::string final_path_;
  std::string temp_path_;
  int fd_ = -1;  // holds the temporary file's lock (ivol/temporary_file.hpp)
  bool committed_ = false;
};

}  // namespace ivol::convert
