// The free-space check before a run (disk_space.hpp).
#include "disk_space.hpp"

#include <sys/stat.h>
#include <sys/statvfs.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>

#include "ivol/error.hpp"
#include "ivol/streaming_writer.hpp"

namespace ivol::convert {
namespace {

std::string directory_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

std::uint64_t saturating_add(std::uint64_t a, std::uint64_t b) {
  return a > ~std::uint64_t{0} - b ? ~std::uint64_t{0} : a + b;
}

std::uint64_t available_bytes(const std::string& directory) {
  if (const char* fake = std::getenv("IVOL_TEST_FREE_BYTES")) return std::strtoull(fake, nullptr, 10);
  struct statvfs fs {};
  if (::statvfs(directory.c_str(), &fs) != 0)
    throw Error(ErrorClass::Io, directory + ": cannot tell its free disk space: " + std::strerror(errno));
  __extension__ const unsigned __int128 bytes = static_cast<unsigned __int128>(fs.f_bavail) * fs.f_frsize;
  return bytes > ~std::uint64_t{0} ? ~std::uint64_t{0} : static_cast<std::uint64_t>(bytes);
}

// "512.0 KiB", "11.4 GiB": the message's sizes (exact bytes beside them).
std::string readable(std::uint64_t bytes) {
  const char* units[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 6) {
    value /= 1024.0;
    ++unit;
  }
  char text[48];
  std::snprintf(text, sizeof text, unit == 0 ? "%.0f %s" : "%.1f %s", value, units[unit]);
  return text;
}

}  // namespace

std::vector<DiskNeed> ivol_disk_needs(const Dims& dims, ValueEncoding encoding, bool octree, const std::string& output,
                                      const std::string& temp_directory) {
  const std::uint64_t width = encoding == ValueEncoding::Float32 ? 4 : 2;
  __extension__ const unsigned __int128 exact = static_cast<unsigned __int128>(dims[0]) * dims[1] * dims[2] * width;
  const std::uint64_t file = exact > ~std::uint64_t{0} ? ~std::uint64_t{0} : static_cast<std::uint64_t>(exact);
  std::vector<DiskNeed> needs{{directory_of(output), file, "the output " + output}};
  if (octree)
    needs.push_back({spill_directory_for(output, temp_directory), file, "the octree writer's spill file", true});
  return needs;
}

void require_disk_space(const std::vector<DiskNeed>& needs) {
  // Needs on one filesystem (one st_dev) add up; the first directory names it.
  struct Filesystem {
    std::string directory;
    std::uint64_t bytes = 0;
    std::string parts;
    bool temporary = false;
  };
  std::map<dev_t, Filesystem> filesystems;
  std::vector<dev_t> order;
  for (const DiskNeed& need : needs) {
    struct stat st {};
    if (::stat(need.directory.c_str(), &st) != 0)
      throw Error(ErrorClass::Io, need.directory + ": cannot write " + need.what + " there: " + std::strerror(errno));
    auto [it, inserted] = filesystems.try_emplace(st.st_dev, Filesystem{need.directory, 0, ""});
    if (inserted) order.push_back(st.st_dev);
    Filesystem& fs = it->second;
    fs.bytes = saturating_add(fs.bytes, need.bytes);
    fs.parts += (fs.parts.empty() ? "" : " + ") + need.what + " " + readable(need.bytes);
    fs.temporary = fs.temporary || need.temporary;
  }
  for (const dev_t dev : order) {
    const Filesystem& fs = filesystems[dev];
    const std::uint64_t available = available_bytes(fs.directory);
    if (available < fs.bytes)
      throw Error(ErrorClass::LimitExceeded,
                  fs.directory + ": not enough free disk for this run: it needs about " + readable(fs.bytes) + " (" +
                      std::to_string(fs.bytes) + " bytes: " + fs.parts +
                      ", estimated as the values uncompressed) and its filesystem has " + readable(available) + " (" +
                      std::to_string(available) + " bytes) available (" +
                      (fs.temporary ? "--temp-dir puts the temporary files on another disk; " : "") +
                      "--no-disk-check skips this estimate)");
  }
}

}  // namespace ivol::convert
