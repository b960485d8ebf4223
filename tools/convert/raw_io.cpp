#include "raw_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

void swap_bytes(std::vector<std::uint8_t>& data, std::size_t width) {
  if (width == 1) return;
  for (std::size_t i = 0; i + width <= data.size(); i += width)
    for (std::size_t a = 0, b = width - 1; a < b; ++a, --b) std::swap(data[i + a], data[i + b]);
}

}  // namespace

DenseVolume read_raw(const std::string& path, const RawLayout& layout) {
  for (auto n : layout.dims)
    if (n == 0) throw Error(ErrorClass::InvalidArgument, path + ": --dims must give three positive sizes");
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw Error(ErrorClass::Io, path + ": cannot open: " + std::strerror(errno));
  const std::uint64_t expected = layout.header_bytes + voxel_count(layout.dims) * sample_size(layout.type);
  if (static_cast<std::uint64_t>(st.st_size) != expected)
    throw Error(ErrorClass::InvalidArgument,
                path + ": the file has " + std::to_string(st.st_size) + " bytes, but " +
                    std::to_string(layout.dims[0]) + "x" + std::to_string(layout.dims[1]) + "x" +
                    std::to_string(layout.dims[2]) + " samples of " + sample_type_name(layout.type) + " after " +
                    std::to_string(layout.header_bytes) + " header bytes need " + std::to_string(expected));
  DenseVolume v = make_dense(layout.dims, layout.type);
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(layout.header_bytes));
  in.read(reinterpret_cast<char*>(v.data.data()), static_cast<std::streamsize>(v.data.size()));
  if (!in) throw Error(ErrorClass::Io, path + ": read failed");
  if (layout.big_endian) swap_bytes(v.data, sample_size(layout.type));
  return v;
}

void write_file_atomically(const std::string& path, const void* bytes, std::size_t size) {
  const auto slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash);
  std::string temp = dir + "/.ivol-tmp-XXXXXX";
  const int fd = mkstemp(temp.data());
  if (fd < 0)
    throw Error(ErrorClass::Io, path + ": cannot create a temporary file in " + dir + ": " + std::strerror(errno));
  const auto* p = static_cast<const std::uint8_t*>(bytes);
  std::size_t left = size;
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int saved = errno;
      ::close(fd);
      ::unlink(temp.c_str());
      throw Error(ErrorClass::Io, path + ": write failed: " + std::strerror(saved));
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  fchmod(fd, 0644);
  if (::fsync(fd) != 0 || ::close(fd) != 0 || ::rename(temp.c_str(), path.c_str()) != 0) {
    const int saved = errno;
    ::unlink(temp.c_str());
    throw Error(ErrorClass::Io, path + ": cannot finish the file: " + std::strerror(saved));
  }
}

void write_raw(const DenseVolume& volume, const std::string& path, bool big_endian) {
  if (!big_endian) {
    write_file_atomically(path, volume.data.data(), volume.data.size());
    return;
  }
  std::vector<std::uint8_t> swapped = volume.data;
  swap_bytes(swapped, sample_size(volume.type));
  write_file_atomically(path, swapped.data(), swapped.size());
}

}  // namespace ivol::convert
