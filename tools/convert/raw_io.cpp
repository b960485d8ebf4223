#include "raw_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "ivol/error.hpp"
#include "sizes.hpp"
#include "slab_io.hpp"
#include "staged_file.hpp"

namespace ivol::convert {
namespace {

void swap_bytes(std::uint8_t* data, std::size_t size, std::size_t width) {
  if (width == 1) return;
  for (std::size_t i = 0; i + width <= size; i += width)
    for (std::size_t a = 0, b = width - 1; a < b; ++a, --b) std::swap(data[i + a], data[i + b]);
}

}  // namespace

namespace {

class RawSlabReader final : public SlabReader {
 public:
  RawSlabReader(const std::string& path, const RawLayout& layout) : path_(path), layout_(layout) {
    for (auto n : layout.dims)
      if (n == 0) throw Error(ErrorClass::InvalidArgument, path + ": --dims must give three positive sizes");
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) throw Error(ErrorClass::Io, path + ": cannot open: " + std::strerror(errno));
    // Checked: 2^31 x 2^31 x 4 bytes wraps to 0 and would match an empty file.
    const std::uint64_t expected = checked_add(
        layout.header_bytes, slab_bytes(layout.dims, layout.dims[2], layout.type, path + ": --dims and --type"),
        path + ": --header-bytes and the samples");
    if (static_cast<std::uint64_t>(st.st_size) != expected)
      throw Error(ErrorClass::InvalidArgument,
                  path + ": the file has " + std::to_string(st.st_size) + " bytes, but " +
                      std::to_string(layout.dims[0]) + "x" + std::to_string(layout.dims[1]) + "x" +
                      std::to_string(layout.dims[2]) + " samples of " + sample_type_name(layout.type) + " after " +
                      std::to_string(layout.header_bytes) + " header bytes need " + std::to_string(expected));
    in_.open(path, std::ios::binary);
    if (!in_) throw Error(ErrorClass::Io, path + ": cannot open for reading");
    shape_.dims = layout.dims;
    shape_.type = layout.type;
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const std::uint64_t slice = slab_bytes(layout_.dims, 1, layout_.type, path_);
    in_.seekg(static_cast<std::streamoff>(layout_.header_bytes + z0 * slice));
    in_.read(static_cast<char*>(out), static_cast<std::streamsize>(count * slice));
    if (!in_) throw Error(ErrorClass::Io, path_ + ": read failed at slice " + std::to_string(z0));
    if (layout_.big_endian) swap_bytes(static_cast<std::uint8_t*>(out), count * slice, sample_size(layout_.type));
  }

  bool reads_rows() const override { return true; }
  bool thick_reads_pay() const override { return false; }  // a read is a pread of whole slices
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override {
    // The sizes were checked against the file's in the constructor.
    const std::uint64_t row = slab_bytes(Dims{layout_.dims[0], 1, 1}, 1, layout_.type, path_);
    const std::uint64_t at = layout_.header_bytes + (std::uint64_t{z} * layout_.dims[1] + y0) * row;
    in_.seekg(static_cast<std::streamoff>(at));
    in_.read(static_cast<char*>(out), static_cast<std::streamsize>(rows * row));
    if (!in_)
      throw Error(ErrorClass::Io, path_ + ": read failed at slice " + std::to_string(z) + " row " + std::to_string(y0));
    if (layout_.big_endian) swap_bytes(static_cast<std::uint8_t*>(out), rows * row, sample_size(layout_.type));
  }

 private:
  std::string path_;
  RawLayout layout_;
  std::ifstream in_;
};

class RawSlabWriter final : public SlabWriter {
 public:
  RawSlabWriter(const std::string& path, const DenseVolume& shape, bool big_endian)
      : path_(path), shape_(shape), big_endian_(big_endian), staged_(path) {
    fd_ = ::open(staged_.temp_path().c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd_ < 0) throw Error(ErrorClass::Io, path + ": cannot open a temporary file: " + std::strerror(errno));
  }
  ~RawSlabWriter() override {
    if (fd_ >= 0) ::close(fd_);
  }
  void write(const void* samples, std::uint32_t count) override {
    write_bytes(samples, slab_bytes(shape_.dims, count, shape_.type, path_));
    at_.slices += count;
  }
  bool writes_rows() const override { return true; }
  void write_rows(const void* samples, std::uint32_t rows) override {
    write_bytes(samples, slab_bytes(Dims{shape_.dims[0], rows, 1}, 1, shape_.type, path_));
    at_.advance(rows, shape_.dims[1]);
  }
  void finish() override {
    if (at_.slices != shape_.dims[2] || at_.rows != 0)
      throw Error(ErrorClass::InvalidArgument, path_ + ": " + std::to_string(at_.slices) + " of " +
                                                   std::to_string(shape_.dims[2]) + " slices written");
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) throw Error(ErrorClass::Io, path_ + ": cannot close the file: " + std::strerror(errno));
    staged_.commit();
  }

 private:
  std::string path_;
  DenseVolume shape_;
  bool big_endian_;
  StagedFile staged_;
  int fd_ = -1;
  RowPosition at_;

  void write_bytes(const void* samples, std::uint64_t bytes) {
    std::vector<std::uint8_t> swapped;
    const auto* p = static_cast<const std::uint8_t*>(samples);
    if (big_endian_) {
      swapped.assign(p, p + bytes);
      swap_bytes(swapped.data(), bytes, sample_size(shape_.type));
      p = swapped.data();
    }
    for (std::size_t done = 0; done < bytes;) {
      const ssize_t n = ::write(fd_, p + done, bytes - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error(ErrorClass::Io, path_ + ": write failed: " + std::strerror(errno));
      done += static_cast<std::size_t>(n);
    }
  }
};

class MemorySlabReader final : public SlabReader {
 public:
  MemorySlabReader(DenseVolume owned, const DenseVolume* viewed)
      : owned_(std::move(owned)), volume_(viewed ? *viewed : owned_) {
    shape_ = shape_of(volume_);
  }
  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const std::uint64_t slice = slab_bytes(volume_.dims, 1, volume_.type, "a volume in memory");
    std::memcpy(out, volume_.data.data() + z0 * slice, count * slice);
  }

 private:
  DenseVolume owned_;
  const DenseVolume& volume_;
};

}  // namespace

std::unique_ptr<SlabReader> open_raw_slabs(const std::string& path, const RawLayout& layout) {
  return std::make_unique<RawSlabReader>(path, layout);
}

std::unique_ptr<SlabReader> memory_slabs(DenseVolume volume) {
  return std::make_unique<MemorySlabReader>(std::move(volume), nullptr);
}

std::unique_ptr<SlabReader> view_slabs(const DenseVolume& volume) {
  return std::make_unique<MemorySlabReader>(DenseVolume{}, &volume);
}

std::unique_ptr<SlabWriter> create_raw_slabs(const std::string& path, const DenseVolume& shape, bool big_endian) {
  return std::make_unique<RawSlabWriter>(path, shape, big_endian);
}

DenseVolume read_raw(const std::string& path, const RawLayout& layout) {
  auto reader = open_raw_slabs(path, layout);
  DenseVolume v = make_dense(layout.dims, layout.type);
  reader->read(0, layout.dims[2], v.data.data());
  return v;
}

void write_raw(const DenseVolume& volume, const std::string& path, bool big_endian) {
  auto writer = create_raw_slabs(path, volume, big_endian);
  writer->write(volume.data.data(), volume.dims[2]);
  writer->finish();
}

}  // namespace ivol::convert
