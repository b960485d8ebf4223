#include "staged_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "ivol/error.hpp"
#include "ivol/temporary_file.hpp"

namespace ivol::convert {
namespace {

[[noreturn]] void io_error(const std::string& path, const std::string& what) {
  throw Error(ErrorClass::Io, path + ": " + what + ": " + std::strerror(errno));
}

}  // namespace

StagedFile::StagedFile(const std::string& final_path) : final_path_(final_path) {
  remove_abandoned_temporaries(final_path);  // left by writers of this file that were killed
  // Kept open, and so locked, until the file is renamed into place.
  fd_ = create_locked_temporary(final_path, temp_path_);
}

StagedFile::~StagedFile() {
  if (!committed_) ::unlink(temp_path_.c_str());
  if (fd_ >= 0) ::close(fd_);
}

void StagedFile::commit() {
  // Reopened by name: a caller may have renamed another finished file onto
  // the temporary name (outputs staged together, each written through its
  // own staged file), and that is the file to flush.
  const int fd = ::open(temp_path_.c_str(), O_RDONLY);
  if (fd < 0) io_error(final_path_, "cannot reopen the finished temporary file " + temp_path_);
  const bool synced = ::fsync(fd) == 0;
  ::close(fd);
  if (!synced) io_error(final_path_, "cannot flush the file to disk");
  rename_into_place(temp_path_, final_path_);
  committed_ = true;
}

}  // namespace ivol::convert
