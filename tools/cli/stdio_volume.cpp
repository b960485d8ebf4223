#include "stdio_volume.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

#include "ivol/error.hpp"
#include "sha256.hpp"

namespace ivol::cli {
namespace {

void swap_bytes(std::uint8_t* data, std::size_t size, std::size_t width) {
  if (width == 1) return;
  for (std::size_t i = 0; i + width <= size; i += width) std::reverse(data + i, data + i + width);
}

StdinDigest finished_digest;  // standard input is one per process

// Reads until `size` bytes or the end of input; returns how many came.
std::size_t read_fully(int fd, std::uint8_t* p, std::size_t size) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::read(fd, p + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(ErrorClass::Io, std::string("standard input: read failed: ") + std::strerror(errno));
    if (n == 0) break;
    done += static_cast<std::size_t>(n);
  }
  return done;
}

class StdinRawReader final : public convert::SlabReader {
 public:
  explicit StdinRawReader(const convert::RawLayout& layout) : layout_(layout) {
    shape_.dims = layout.dims;
    shape_.type = layout.type;
    slice_ = std::uint64_t{layout.dims[0]} * layout.dims[1] * convert::sample_size(layout.type);
    std::vector<std::uint8_t> header(static_cast<std::size_t>(std::min<std::uint64_t>(layout.header_bytes, 1 << 20)));
    for (std::uint64_t left = layout.header_bytes; left > 0;) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(left, header.size()));
      if (take(header.data(), n) != n)
        throw Error(ErrorClass::InvalidArgument,
                    "standard input: ended inside the " + std::to_string(layout.header_bytes) + "-byte header");
      left -= n;
    }
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    auto* dst = static_cast<std::uint8_t*>(out);
    // Slices still held from the previous slab (a margin's overlap).
    const std::uint32_t held_end = held_first_ + held_count_;
    const std::uint32_t reuse = z0 >= held_first_ && z0 < held_end ? std::min(held_end - z0, count) : 0;
    const std::uint32_t first_new = z0 + reuse;
    // Anything else already read is gone: a stream cannot be read twice.
    if (reuse < count && first_new < next_)
      throw Error(ErrorClass::InvalidArgument,
                  "standard input: this conversion reads the volume twice (--keep threshold=otsu); give a file");
    if (reuse) std::memcpy(dst, held_.data() + (z0 - held_first_) * slice_, reuse * slice_);
    if (reuse < count) {
      if (first_new > next_) skip_to(first_new);
      const std::uint64_t want = (count - reuse) * slice_;
      const std::size_t got = take(dst + reuse * slice_, want);
      if (got != want)
        throw Error(ErrorClass::InvalidArgument, "standard input: ended " + std::to_string(first_new * slice_ + got) +
                                                     " bytes into the volume; " + dims_text() + " needs " +
                                                     std::to_string(total_bytes()));
      next_ = z0 + count;
      if (next_ == layout_.dims[2]) expect_end();
    }
    held_.assign(dst, dst + count * slice_);
    held_first_ = z0;
    held_count_ = count;
    if (layout_.big_endian) swap_bytes(dst, count * slice_, convert::sample_size(layout_.type));
  }

  // Rows in order, each once (a slice beyond the memory budget goes in
  // bands of rows); not mixed with read().
  bool reads_rows() const override { return true; }
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override {
    if (z != next_ || y0 != next_row_ || rows > layout_.dims[1] - y0)
      throw Error(ErrorClass::InvalidArgument, "standard input: rows " + std::to_string(y0) + " of slice " +
                                                   std::to_string(z) +
                                                   " asked for out of order; a stream is read once");
    auto* dst = static_cast<std::uint8_t*>(out);
    const std::uint64_t row = slice_ / layout_.dims[1];
    const std::uint64_t want = std::uint64_t{rows} * row;
    const std::size_t got = take(dst, want);
    if (got != want)
      throw Error(ErrorClass::InvalidArgument, "standard input: ended " + std::to_string(z * slice_ + y0 * row + got) +
                                                   " bytes into the volume; " + dims_text() + " needs " +
                                                   std::to_string(total_bytes()));
    next_row_ += rows;
    if (next_row_ == layout_.dims[1]) {
      next_row_ = 0;
      if (++next_ == layout_.dims[2]) expect_end();
    }
    if (layout_.big_endian) swap_bytes(dst, want, convert::sample_size(layout_.type));
  }

 private:
  void skip_to(std::uint32_t z) {
    std::vector<std::uint8_t> sink(slice_);
    for (; next_ < z; ++next_)
      if (take(sink.data(), slice_) != slice_)
        throw Error(ErrorClass::InvalidArgument, "standard input: ended before slice " + std::to_string(z));
  }
  // After the volume's last byte: the end of input, and the digest is known.
  void expect_end() {
    std::uint8_t extra = 0;
    if (take(&extra, 1) != 0)
      throw Error(ErrorClass::InvalidArgument,
                  "standard input: more bytes than " + dims_text() + " (" + std::to_string(total_bytes()) + ")");
    finished_digest = {bytes_, sha_.hex()};
  }
  // Every byte of standard input goes through here, into the digest.
  std::size_t take(std::uint8_t* p, std::size_t size) {
    const std::size_t got = read_fully(STDIN_FILENO, p, size);
    sha_.update(p, got);
    bytes_ += got;
    return got;
  }
  std::uint64_t total_bytes() const { return slice_ * layout_.dims[2]; }
  std::string dims_text() const {
    return std::to_string(layout_.dims[0]) + "x" + std::to_string(layout_.dims[1]) + "x" +
           std::to_string(layout_.dims[2]) + " " + convert::sample_type_name(layout_.type);
  }

  convert::RawLayout layout_;
  std::uint64_t slice_ = 0;
  std::uint32_t next_ = 0;          // the next slice standard input gives
  std::uint32_t next_row_ = 0;      // and its next row (read_rows)
  std::vector<std::uint8_t> held_;  // the last slab, as read (before any byte swap)
  std::uint32_t held_first_ = 0, held_count_ = 0;
  Sha256 sha_;
  std::uint64_t bytes_ = 0;
};

class StdoutRawWriter final : public convert::SlabWriter {
 public:
  StdoutRawWriter(const convert::DenseVolume& shape, bool big_endian) : shape_(shape), big_endian_(big_endian) {}
  void write(const void* samples, std::uint32_t count) override {
    put(samples, std::size_t{count} * shape_.dims[0] * shape_.dims[1] * convert::sample_size(shape_.type));
    at_.slices += count;
  }
  bool writes_rows() const override { return true; }
  void write_rows(const void* samples, std::uint32_t rows) override {
    put(samples, std::size_t{rows} * shape_.dims[0] * convert::sample_size(shape_.type));
    at_.advance(rows, shape_.dims[1]);
  }
  void finish() override {
    if (at_.slices != shape_.dims[2] || at_.rows != 0)
      throw Error(ErrorClass::Io, "standard output: " + std::to_string(at_.slices) + " of " +
                                      std::to_string(shape_.dims[2]) + " slices written");
  }

 private:
  void put(const void* samples, std::size_t bytes) {
    const std::size_t width = convert::sample_size(shape_.type);
    const auto* p = static_cast<const std::uint8_t*>(samples);
    std::vector<std::uint8_t> swapped;
    if (big_endian_) {
      swapped.assign(p, p + bytes);
      swap_bytes(swapped.data(), bytes, width);
      p = swapped.data();
    }
    for (std::size_t done = 0; done < bytes;) {
      const ssize_t n = ::write(STDOUT_FILENO, p + done, bytes - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error(ErrorClass::Io, std::string("standard output: write failed: ") + std::strerror(errno));
      done += static_cast<std::size_t>(n);
    }
  }

  convert::DenseVolume shape_;
  bool big_endian_;
  convert::RowPosition at_;
};

}  // namespace

std::unique_ptr<convert::SlabReader> stdin_raw_slabs(const convert::RawLayout& layout) {
  for (auto n : layout.dims)
    if (n == 0) throw Error(ErrorClass::InvalidArgument, "--dims must give three positive sizes");
  return std::make_unique<StdinRawReader>(layout);
}

StdinDigest stdin_digest() { return finished_digest; }

std::unique_ptr<convert::SlabWriter> stdout_raw_slabs(const convert::DenseVolume& shape, bool big_endian) {
  return std::make_unique<StdoutRawWriter>(shape, big_endian);
}

}  // namespace ivol::cli
