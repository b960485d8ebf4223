// Locked temporary files, and the removal of those whose writer died.
#include "ivol/temporary_file.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <random>
#include <set>
#include <vector>

#include "ivol/error.hpp"

namespace ivol {
namespace {

std::string directory_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

std::string base_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string temporary_prefix(const std::string& final_path) { return "." + base_of(final_path) + ".tmp-"; }

[[noreturn]] void io_error(const std::string& path, const std::string& what) {
  throw Error(ErrorClass::Io, path + ": " + what + ": " + std::strerror(errno));
}

// Open-file-description locks (Linux fcntl F_OFD_SETLK): held by this
// descriptor alone, not dropped when the process closes another descriptor
// of the file, and independent of flock(2), which libraries writing into
// the file by name (HDF5) take themselves.
bool lock_whole_file(int fd, short type) {
  struct flock lock {};
  lock.l_type = type;
  lock.l_whence = SEEK_SET;
  return ::fcntl(fd, F_OFD_SETLK, &lock) == 0;
}

std::string random_suffix(std::mt19937_64& rng) {
  static const char kLetters[] = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789";
  std::string s(6, 'x');
  for (char& c : s) c = kLetters[rng() % (sizeof kLetters - 1)];
  return s;
}

// O_TMPFILE: an unnamed file, locked, then given its name with linkat.
int create_unnamed_then_link(const std::string& final_path, std::string& temp_path) {
#ifdef O_TMPFILE
  const std::string directory = directory_of(final_path);
  const int fd = ::open(directory.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0644);
  if (fd < 0) return -1;  // not supported here: the caller falls back
  if (!lock_whole_file(fd, F_WRLCK)) {
    ::close(fd);
    io_error(final_path, "cannot lock a temporary file in " + directory);
  }
  std::random_device seed;
  std::mt19937_64 rng((static_cast<std::uint64_t>(seed()) << 32) ^ seed() ^ static_cast<std::uint64_t>(::getpid()));
  const std::string proc = "/proc/self/fd/" + std::to_string(fd);
  for (int attempt = 0; attempt < 100; ++attempt) {
    const std::string name = directory + "/" + temporary_prefix(final_path) + random_suffix(rng);
    if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, name.c_str(), AT_SYMLINK_FOLLOW) == 0) {
      temp_path = name;
      return fd;
    }
    if (errno != EEXIST) break;
  }
  ::close(fd);
  return -1;
#else
  (void)final_path;
  (void)temp_path;
  return -1;
#endif
}

// The paths given to refuse_to_replace, absolute and normalised so that
// "out.raw" and "./out.raw" are one.
std::mutex protected_mutex;
std::set<std::string>& protected_paths() {
  static std::set<std::string> paths;
  return paths;
}
std::string path_key(const std::string& path) {
  std::error_code ec;
  const auto absolute = std::filesystem::absolute(path, ec);
  return (ec ? std::filesystem::path(path) : absolute).lexically_normal().string();
}
bool is_protected(const std::string& path) {
  std::lock_guard<std::mutex> lock(protected_mutex);
  return protected_paths().count(path_key(path)) != 0;
}

// Renames without replacing: EEXIST when something is at final_path.
int rename_no_replace(const std::string& temp_path, const std::string& final_path) {
#ifdef RENAME_NOREPLACE
  if (::renameat2(AT_FDCWD, temp_path.c_str(), AT_FDCWD, final_path.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return -1;
#endif
  // link() never replaces either; then the temporary name goes.
  if (::link(temp_path.c_str(), final_path.c_str()) != 0) return -1;
  ::unlink(temp_path.c_str());
  return 0;
}

}  // namespace

void refuse_to_replace(const std::string& final_path) {
  std::lock_guard<std::mutex> lock(protected_mutex);
  protected_paths().insert(path_key(final_path));
}

int create_locked_temporary(const std::string& final_path, std::string& temp_path) {
  if (final_path.empty()) throw Error(ErrorClass::InvalidArgument, "output path is empty");
  if (base_of(final_path).empty())
    throw Error(ErrorClass::InvalidArgument, final_path + ": output path names a directory");
  const int linked = create_unnamed_then_link(final_path, temp_path);
  if (linked >= 0) return linked;
  // mkstemp, then the lock: a cleaner could only act in the moment between
  // the two, and only on a file still empty.
  std::string pattern = directory_of(final_path) + "/" + temporary_prefix(final_path) + "XXXXXX";
  std::vector<char> name(pattern.begin(), pattern.end());
  name.push_back('\0');
  const int fd = ::mkstemp(name.data());
  if (fd < 0) io_error(final_path, "cannot create a temporary file in " + directory_of(final_path));
  if (!lock_whole_file(fd, F_WRLCK)) {
    ::unlink(name.data());
    ::close(fd);
    io_error(final_path, "cannot lock a temporary file in " + directory_of(final_path));
  }
  // mkstemp makes the file private (0600); an output file should be as readable as any other.
  ::fchmod(fd, 0644);
  temp_path.assign(name.data());
  return fd;
}

void rename_into_place(const std::string& temp_path, const std::string& final_path) {
  if (is_protected(final_path)) {
    if (rename_no_replace(temp_path, final_path) != 0) {
      if (errno == EEXIST)
        throw Error(ErrorClass::InvalidArgument, final_path +
                                                     ": appeared while this file was written; not replaced (use "
                                                     "--force to replace it)");
      io_error(final_path, "cannot rename the finished file into place");
    }
  } else if (::rename(temp_path.c_str(), final_path.c_str()) != 0) {
    io_error(final_path, "cannot rename the finished file into place");
  }
  const int dir = ::open(directory_of(final_path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

std::size_t remove_abandoned_temporaries(const std::string& final_path) {
  const std::string directory = directory_of(final_path);
  const std::string prefix = temporary_prefix(final_path);
  DIR* dir = ::opendir(directory.c_str());
  if (dir == nullptr) return 0;
  std::vector<std::string> candidates;
  while (const dirent* entry = ::readdir(dir)) {
    const std::string name = entry->d_name;
    if (name.size() == prefix.size() + 6 && name.compare(0, prefix.size(), prefix) == 0) candidates.push_back(name);
  }
  ::closedir(dir);
  std::size_t removed = 0;
  for (const std::string& name : candidates) {
    const std::string path = directory + "/" + name;
    const int fd = ::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) continue;
    struct stat st {};
    // Holding a read lock while unlinking: no live writer holds its write lock.
    if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && lock_whole_file(fd, F_RDLCK) && ::unlink(path.c_str()) == 0)
      ++removed;
    ::close(fd);
  }
  return removed;
}

}  // namespace ivol
