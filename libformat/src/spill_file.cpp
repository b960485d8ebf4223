// The compressed, unnamed spill file of the streaming octree writer.
#include "spill_file.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zstd.h>

#include <cerrno>
#include <cstring>
#include <memory>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

struct CompressContext {
  ZSTD_CCtx* context = ZSTD_createCCtx();
  ~CompressContext() { ZSTD_freeCCtx(context); }
};
struct DecompressContext {
  ZSTD_DCtx* context = ZSTD_createDCtx();
  ~DecompressContext() { ZSTD_freeDCtx(context); }
};

// Byte k of every element together: the high bytes of node words and of
// values vary slowly and compress apart from the noisy low ones.
void split_planes(const std::uint8_t* in, std::uint64_t count, std::size_t width, std::uint8_t* out) {
  for (std::size_t b = 0; b < width; ++b)
    for (std::uint64_t e = 0; e < count; ++e) out[b * count + e] = in[e * width + b];
}
void join_planes(const std::uint8_t* in, std::uint64_t count, std::size_t width, std::uint8_t* out) {
  for (std::size_t b = 0; b < width; ++b)
    for (std::uint64_t e = 0; e < count; ++e) out[e * width + b] = in[b * count + e];
}

}  // namespace

PackedChunk pack_chunk(const void* elements, std::uint64_t count, std::size_t width, int zstd_level) {
  PackedChunk chunk;
  chunk.raw_bytes = count * width;
  if (count == 0) return chunk;
  const auto* raw = static_cast<const std::uint8_t*>(elements);
  std::vector<std::uint8_t> planes(chunk.raw_bytes);
  split_planes(raw, count, width, planes.data());
  thread_local CompressContext zstd;
  if (zstd.context == nullptr) throw Error(ErrorClass::Io, "spill file: cannot create a zstd context");
  ZSTD_CCtx_reset(zstd.context, ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(zstd.context, ZSTD_c_compressionLevel, zstd_level);
  chunk.stored.resize(ZSTD_compressBound(chunk.raw_bytes));
  const std::size_t size =
      ZSTD_compress2(zstd.context, chunk.stored.data(), chunk.stored.size(), planes.data(), planes.size());
  if (ZSTD_isError(size))
    throw Error(ErrorClass::Io, std::string("spill file: zstd compression failed: ") + ZSTD_getErrorName(size));
  if (size >= chunk.raw_bytes) {
    chunk.stored.assign(raw, raw + chunk.raw_bytes);  // stored as it is
  } else {
    chunk.stored.resize(size);
  }
  return chunk;
}

SpillFile::SpillFile(const std::string& directory) : directory_(directory) {
#ifdef O_TMPFILE
  fd_ = ::open(directory.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
#endif
  if (fd_ < 0) {
    // No O_TMPFILE on this filesystem: a name, unlinked at once.
    std::string name = directory + "/.ivol-spill-XXXXXX";
    fd_ = ::mkostemp(name.data(), O_CLOEXEC);
    if (fd_ < 0)
      throw Error(ErrorClass::Io,
                  directory + ": cannot create the temporary spill file (--temp-dir): " + std::strerror(errno));
    ::unlink(name.c_str());
  }
}

SpillFile::~SpillFile() { ::close(fd_); }

std::uint64_t SpillFile::append(const std::uint8_t* data, std::size_t size) {
  const std::uint64_t at = size_;
  for (std::size_t done = 0; done < size;) {
    const ssize_t n = ::pwrite(fd_, data + done, size - done, static_cast<off_t>(at + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw Error(ErrorClass::Io,
                  directory_ + ": writing the temporary spill file failed: " + std::strerror(n == 0 ? EIO : errno));
    done += static_cast<std::size_t>(n);
  }
  size_ += size;
  return at;
}

void SpillFile::read_raw(std::uint64_t at, void* out, std::size_t size) const {
  auto* p = static_cast<std::uint8_t*>(out);
  for (std::size_t done = 0; done < size;) {
    const ssize_t n = ::pread(fd_, p + done, size - done, static_cast<off_t>(at + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw Error(ErrorClass::Io,
                  directory_ + ": reading the temporary spill file failed: " + std::strerror(n == 0 ? EIO : errno));
    done += static_cast<std::size_t>(n);
  }
}

void SpillFile::read_chunk(std::uint64_t at, std::uint64_t stored_bytes, void* out, std::uint64_t count,
                           std::size_t width) const {
  const std::uint64_t raw_bytes = count * width;
  if (stored_bytes == raw_bytes) return read_raw(at, out, raw_bytes);
  std::vector<std::uint8_t> stored(stored_bytes), planes(raw_bytes);
  read_raw(at, stored.data(), stored.size());
  thread_local DecompressContext zstd;
  if (zstd.context == nullptr) throw Error(ErrorClass::Io, "spill file: cannot create a zstd context");
  const std::size_t got = ZSTD_decompressDCtx(zstd.context, planes.data(), planes.size(), stored.data(), stored.size());
  if (ZSTD_isError(got) || got != raw_bytes)
    throw Error(ErrorClass::Io, directory_ + ": the temporary spill file does not decode (" +
                                    (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short chunk") + ")");
  join_planes(planes.data(), count, width, static_cast<std::uint8_t*>(out));
}

}  // namespace ivol::detail
