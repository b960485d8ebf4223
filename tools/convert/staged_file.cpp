#include "staged_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

std::string directory_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

[[noreturn]] void io_error(const std::string& path, const std::string& what) {
  throw Error(ErrorClass::Io, path + ": " + what + ": " + std::strerror(errno));
}

}  // namespace

StagedFile::StagedFile(const std::string& final_path) : final_path_(final_path) {
  if (final_path.empty()) throw Error(ErrorClass::InvalidArgument, "output path is empty");
  const std::size_t slash = final_path.find_last_of('/');
  const std::string base = slash == std::string::npos ? final_path : final_path.substr(slash + 1);
  if (base.empty()) throw Error(ErrorClass::InvalidArgument, final_path + ": output path names a directory");
  std::string pattern = directory_of(final_path) + "/." + base + ".tmp-XXXXXX";
  std::vector<char> name(pattern.begin(), pattern.end());
  name.push_back('\0');
  const int fd = ::mkstemp(name.data());
  if (fd < 0) io_error(final_path, "cannot create a temporary file in " + directory_of(final_path));
  // mkstemp makes the file private (0600); an output file should be as readable as any other.
  ::fchmod(fd, 0644);
  ::close(fd);
  temp_path_.assign(name.data());
}

StagedFile::~StagedFile() {
  if (!committed_) ::unlink(temp_path_.c_str());
}

void StagedFile::commit() {
  const int fd = ::open(temp_path_.c_str(), O_RDONLY);
  if (fd < 0) io_error(final_path_, "cannot reopen the finished temporary file " + temp_path_);
  const bool synced = ::fsync(fd) == 0;
  ::close(fd);
  if (!synced) io_error(final_path_, "cannot flush the file to disk");
  if (::rename(temp_path_.c_str(), final_path_.c_str()) != 0)
    io_error(final_path_, "cannot rename the finished file into place");
  committed_ = true;
  // Make the rename itself durable.
  const int dir = ::open(directory_of(final_path_).c_str(), O_RDONLY | O_DIRECTORY);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

}  // namespace ivol::convert
