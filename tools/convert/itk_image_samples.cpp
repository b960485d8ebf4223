#include "itk_image_samples.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "ivol/error.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

constexpr std::size_t kInputChunk = 1 << 20;

void swap_to_native(std::uint8_t* data, std::uint64_t size, std::size_t width, bool big_endian) {
  constexpr bool host_big = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
  if (width == 1 || big_endian == host_big) return;
  for (std::uint64_t i = 0; i + width <= size; i += width) std::reverse(data + i, data + i + width);
}

}  // namespace

ImageSamples::ImageSamples(const ImageHeader& header) : header_(header) {
  fd_ = ::open(header_.data_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0)
    throw Error(ErrorClass::Io, header_.path + ": " + header_.format + " data file " + header_.data_path +
                                    ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    fd_ = -1;
    throw Error(ErrorClass::InvalidArgument, header_.data_path + ": not a regular file");
  }
  const auto size = static_cast<std::uint64_t>(st.st_size);
  const std::uint64_t bytes = header_.data_bytes();
  const std::string samples = std::to_string(header_.size[0]) + "x" + std::to_string(header_.size[1]) + "x" +
                              std::to_string(header_.size[2]) + " " + element_name(header_.element) + " samples";
  if (header_.encoding == ImageEncoding::Raw) {
    const std::uint64_t after = size > header_.data_offset ? size - header_.data_offset : 0;
    // Attached data must fill the rest of the file; a separate data file may
    // hold more (ITK's HeaderSize skips a header, not a trailer).
    const bool attached = header_.data_path == header_.path;
    if (after < bytes || (attached && after != bytes)) {
      ::close(fd_);
      fd_ = -1;
      throw Error(ErrorClass::InvalidArgument,
                  header_.data_path + ": " + std::to_string(after) + " bytes after the " + header_.format +
                      " header's offset " + std::to_string(header_.data_offset) + ", but " + samples + " are " +
                      std::to_string(bytes) + " bytes");
    }
    data_end_ = header_.data_offset + bytes;
  } else {
    data_end_ = size;
    if (header_.compressed_bytes > 0) {
      if (header_.data_offset + header_.compressed_bytes > size) {
        ::close(fd_);
        fd_ = -1;
        throw Error(ErrorClass::InvalidArgument,
                    header_.data_path + ": CompressedDataSize " + std::to_string(header_.compressed_bytes) +
                        " reaches past the end of the file (" + std::to_string(size) + " bytes)");
      }
      data_end_ = header_.data_offset + header_.compressed_bytes;
    }
    if (header_.data_offset > size) {
      ::close(fd_);
      fd_ = -1;
      throw Error(ErrorClass::InvalidArgument, header_.data_path + ": the data start past the end of the file");
    }
  }
}

ImageSamples::~ImageSamples() {
  if (stream_open_) inflateEnd(&stream_);
  if (fd_ >= 0) ::close(fd_);
}

std::string ImageSamples::where(std::uint64_t at) const {
  return header_.data_path + ": " + header_.format + " samples, byte " + std::to_string(at);
}

void ImageSamples::read_raw(std::uint64_t at, std::uint64_t size, std::uint8_t* out) {
  for (std::uint64_t done = 0; done < size;) {
    const ssize_t n = ::pread(fd_, out + done, size - done, static_cast<off_t>(at + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(ErrorClass::Io, where(at + done) + ": read failed: " + std::strerror(errno));
    if (n == 0) throw Error(ErrorClass::Io, where(at + done) + ": the file was cut short after opening");
    done += static_cast<std::uint64_t>(n);
  }
}

void ImageSamples::restart() {
  if (stream_open_) inflateEnd(&stream_);
  stream_ = z_stream{};
  // 15 + 32: zlib or gzip, told by the stream's own header.
  if (inflateInit2(&stream_, 15 + 32) != Z_OK)
    throw Error(ErrorClass::LimitExceeded, header_.data_path + ": cannot start zlib");
  stream_open_ = true;
  stream_ended_ = false;
  file_at_ = header_.data_offset;
  produced_ = 0;
}

std::uint64_t ImageSamples::produce(std::uint8_t* out, std::uint64_t size) {
  std::uint64_t done = 0;
  while (done < size) {
    if (stream_ended_)
      throw Error(ErrorClass::Malformed, where(produced_) + ": the compressed data end after " +
                                             std::to_string(produced_) + " of the " +
                                             std::to_string(header_.data_bytes()) + " bytes the samples need");
    if (stream_.avail_in == 0) {
      const std::uint64_t left = data_end_ - file_at_;
      if (left == 0)
        throw Error(ErrorClass::Malformed, where(produced_) + ": the compressed stream is cut short after " +
                                               std::to_string(produced_) + " of " +
                                               std::to_string(header_.data_bytes()) + " bytes");
      input_.resize(kInputChunk);
      const auto chunk = static_cast<std::size_t>(std::min<std::uint64_t>(left, kInputChunk));
      read_raw(file_at_, chunk, input_.data());
      file_at_ += chunk;
      stream_.next_in = input_.data();
      stream_.avail_in = static_cast<uInt>(chunk);
    }
    const auto want = static_cast<uInt>(std::min<std::uint64_t>(size - done, 1u << 30));
    stream_.next_out = out + done;
    stream_.avail_out = want;
    const int status = ::inflate(&stream_, Z_NO_FLUSH);
    const uInt got = want - stream_.avail_out;
    done += got;
    produced_ += got;
    if (status == Z_STREAM_END) {
      stream_ended_ = true;
    } else if (status != Z_OK && !(status == Z_BUF_ERROR && got > 0)) {
      throw Error(ErrorClass::Malformed, where(produced_) + ": the compressed data are damaged (zlib: " +
                                             (stream_.msg ? stream_.msg : std::to_string(status)) + ")");
    }
  }
  // After the last sample the stream must end here, with nothing more.
  if (produced_ == header_.data_bytes() && !stream_ended_) {
    std::uint8_t extra = 0;
    stream_.next_out = &extra;
    stream_.avail_out = 1;
    if (stream_.avail_in == 0 && file_at_ < data_end_) {
      input_.resize(kInputChunk);
      const auto chunk = static_cast<std::size_t>(std::min<std::uint64_t>(data_end_ - file_at_, kInputChunk));
      read_raw(file_at_, chunk, input_.data());
      file_at_ += chunk;
      stream_.next_in = input_.data();
      stream_.avail_in = static_cast<uInt>(chunk);
    }
    const int status = ::inflate(&stream_, Z_NO_FLUSH);
    if (stream_.avail_out == 0)
      throw Error(ErrorClass::Malformed, where(produced_) + ": the compressed data hold more than the " +
                                             std::to_string(header_.data_bytes()) + " bytes the header's sizes need");
    if (status != Z_STREAM_END)
      throw Error(ErrorClass::Malformed, where(produced_) + ": the compressed stream does not end after the samples");
    stream_ended_ = true;
  }
  return done;
}

void ImageSamples::inflate(std::uint64_t at, std::uint64_t size, std::uint8_t* out) {
  if (!stream_open_ || at < produced_) restart();
  while (produced_ < at) {
    skip_.resize(kInputChunk);
    produce(skip_.data(), std::min<std::uint64_t>(at - produced_, skip_.size()));
  }
  produce(out, size);
}

void ImageSamples::read(std::uint64_t first, std::uint64_t count, void* out) {
  const std::size_t width = element_size(header_.element);
  const std::string what = header_.data_path + ": samples " + std::to_string(first) + " + " + std::to_string(count);
  const std::uint64_t at = checked_mul(first, width, what);
  const std::uint64_t size = checked_mul(count, width, what);
  if (checked_add(at, size, what) > header_.data_bytes())
    throw Error(ErrorClass::InvalidArgument, what + " reach past the image's samples");
  auto* bytes = static_cast<std::uint8_t*>(out);
  if (header_.encoding == ImageEncoding::Raw || inflated_to_file_)
    read_raw((inflated_to_file_ ? 0 : header_.data_offset) + at, size, bytes);
  else
    inflate(at, size, bytes);
  swap_to_native(bytes, size, width, header_.big_endian);
}

void ImageSamples::inflate_to_file() {
  if (header_.encoding == ImageEncoding::Raw || inflated_to_file_) return;
  const char* dir = std::getenv("TMPDIR");
  const std::string folder = dir && *dir ? dir : "/tmp";
  const int copy = ::open(folder.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (copy < 0)
    throw Error(ErrorClass::Io, header_.path + ": cannot make a temporary file in " + folder +
                                    " for the inflated samples: " + std::strerror(errno));
  restart();
  std::vector<std::uint8_t> chunk(kInputChunk);
  const std::uint64_t total = header_.data_bytes();
  try {
    while (produced_ < total) {
      const std::uint64_t n = produce(chunk.data(), std::min<std::uint64_t>(total - produced_, chunk.size()));
      for (std::uint64_t done = 0; done < n;) {
        const ssize_t w = ::write(copy, chunk.data() + done, n - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0)
          throw Error(ErrorClass::Io, header_.path + ": writing the inflated samples to " + folder + ": " +
                                          std::strerror(errno));
        done += static_cast<std::uint64_t>(w);
      }
    }
  } catch (...) {
    ::close(copy);
    throw;
  }
  inflateEnd(&stream_);
  stream_open_ = false;
  ::close(fd_);
  fd_ = copy;
  inflated_to_file_ = true;
}

}  // namespace ivol::convert
