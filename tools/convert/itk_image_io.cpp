#include "itk_image_io.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <vector>

#include "itk_image_header.hpp"
#include "itk_image_samples.hpp"
#include "ivol/error.hpp"
#include "sizes.hpp"
#include "staged_file.hpp"
#include "volume_metadata.hpp"

namespace ivol::convert {
namespace {

std::string lower_extension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

SampleType volume_type(const ImageHeader& h) {
  switch (h.element) {
    case ImageElement::UInt8:
      return SampleType::UInt8;
    case ImageElement::Int8:
    case ImageElement::Int16:
      return SampleType::Int16;
    case ImageElement::UInt16:
      return SampleType::UInt16;
    case ImageElement::Float32:
      return SampleType::Float32;
    default:
      break;
  }
  throw Error(ErrorClass::InvalidArgument,
              h.path + ": " + h.format + " " + element_name(h.element) +
                  " samples: ivol holds uint8, int8/int16, uint16, binary16 and float32 volumes; convert the image "
                  "to one of these first (nothing written)");
}

class ItkImageSlabReader final : public SlabReader {
 public:
  explicit ItkImageSlabReader(const std::string& path) : samples_(read_image_header(path)) {
    const ImageHeader& h = samples_.header();
    shape_.dims = {static_cast<std::uint32_t>(h.size[0]), static_cast<std::uint32_t>(h.size[1]),
                   static_cast<std::uint32_t>(h.size[2])};
    shape_.type = volume_type(h);
    shape_.voxel_size = h.spacing;
    shape_.origin = h.origin;
    shape_.has_geometry = h.has_spacing || h.has_origin;
    if (h.has_spacing) shape_.voxel_size_from = h.spacing_field;
    if (h.has_origin) shape_.origin_from = h.origin_field;
    if (!h.unit.empty()) {
      shape_.unit = normalise_length_unit(h.unit);
      shape_.unit_from = "NRRD space units";
    } else if (h.format == "MetaImage" && shape_.has_geometry) {
      shape_.unit = "mm";
      shape_.unit_from = "ITK's and RTK's convention, MetaImage having no unit field";
    }
    widen_ = h.element == ImageElement::Int8;
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const std::uint64_t slice = std::uint64_t{shape_.dims[0]} * shape_.dims[1];
    read_samples(slice * z0, slice * count, out);
  }

  bool reads_rows() const override { return true; }
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override {
    const std::uint64_t first = (std::uint64_t{z} * shape_.dims[1] + y0) * shape_.dims[0];
    read_samples(first, std::uint64_t{rows} * shape_.dims[0], out);
  }

 private:
  void read_samples(std::uint64_t first, std::uint64_t n, void* out) {
    samples_.read(first, n, out);
    if (!widen_) return;
    // int8 → int16 in place, from the end, so that no sample is overwritten
    // before it is read.
    const auto* bytes = static_cast<const std::int8_t*>(out);
    auto* wide = static_cast<std::int16_t*>(out);
    for (std::uint64_t i = n; i-- > 0;) wide[i] = bytes[i];
  }

  ImageSamples samples_;
  bool widen_ = false;
};

// The shortest text that reads back as the same double.
std::string exact(double v) {
  char text[40];
  const auto result = std::to_chars(text, text + sizeof text, v);
  return std::string(text, result.ptr);
}

class ItkImageSlabWriter final : public SlabWriter {
 public:
  ItkImageSlabWriter(const std::string& path, const DenseVolume& shape)
      : path_(path), shape_(shape), staged_(path), nrrd_(lower_extension(path) == ".nrrd") {
    if (!nrrd_ && lower_extension(path) != ".mha")
      throw Error(ErrorClass::InvalidArgument, path + ": ITK images are written as .mha or .nrrd (one file)");
    if (shape.type == SampleType::Float16)
      throw Error(ErrorClass::InvalidArgument,
                  path + ": MetaImage and NRRD have no binary16 type; float32 holds every value exactly");
    fd_ = ::open(staged_.temp_path().c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd_ < 0) throw Error(ErrorClass::Io, path + ": cannot open a temporary file: " + std::strerror(errno));
    const std::string header = nrrd_ ? nrrd_header() : metaimage_header();
    put(header.data(), header.size());
    if (nrrd_) {
      // 15 + 16: a gzip stream, as NRRD's "encoding: gzip" says.
      if (deflateInit2(&stream_, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
        throw Error(ErrorClass::LimitExceeded, path + ": cannot start zlib");
      deflating_ = true;
    }
  }
  ~ItkImageSlabWriter() override {
    if (deflating_) deflateEnd(&stream_);
    if (fd_ >= 0) ::close(fd_);
  }

  void write(const void* samples, std::uint32_t count) override {
    const std::uint64_t bytes = slab_bytes(shape_.dims, count, shape_.type, path_);
    if (nrrd_)
      deflate_some(samples, bytes, Z_NO_FLUSH);
    else
      put(samples, bytes);
    at_.slices += count;
  }
  bool writes_rows() const override { return true; }
  void write_rows(const void* samples, std::uint32_t rows) override {
    const std::uint64_t bytes = slab_bytes(Dims{shape_.dims[0], rows, 1}, 1, shape_.type, path_);
    if (nrrd_)
      deflate_some(samples, bytes, Z_NO_FLUSH);
    else
      put(samples, bytes);
    at_.advance(rows, shape_.dims[1]);
  }

  void finish() override {
    if (at_.slices != shape_.dims[2] || at_.rows != 0)
      throw Error(ErrorClass::InvalidArgument, path_ + ": " + std::to_string(at_.slices) + " of " +
                                                   std::to_string(shape_.dims[2]) + " slices written");
    if (nrrd_) deflate_some(nullptr, 0, Z_FINISH);
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) throw Error(ErrorClass::Io, path_ + ": cannot close the file: " + std::strerror(errno));
    staged_.commit();
  }

 private:
  // MetaImage has no unit: millimetres, as ITK's and RTK's tools read it.
  // Scaled by a power of ten in one correctly rounded step (5 um is 0.005
  // mm, not 0.005000000000000001).
  double in_mm(double value) const {
    static const std::pair<const char*, int> kExponents[] = {{"m", 3}, {"cm", 1}, {"mm", 0}, {"um", -3}, {"nm", -6}};
    for (const auto& [unit, exponent] : kExponents)
      if (shape_.unit == unit)
        return exponent >= 0 ? value * std::pow(10.0, exponent) : value / std::pow(10.0, -exponent);
    throw Error(ErrorClass::InvalidArgument,
                path_ + ": the volume's unit '" + shape_.unit + "' is not a length MetaImage's millimetres can state");
  }

  std::string element() const {
    switch (shape_.type) {
      case SampleType::UInt8:
        return nrrd_ ? "uint8" : "MET_UCHAR";
      case SampleType::Int16:
        return nrrd_ ? "int16" : "MET_SHORT";
      case SampleType::UInt16:
        return nrrd_ ? "uint16" : "MET_USHORT";
      default:
        return nrrd_ ? "float" : "MET_FLOAT";
    }
  }

  std::string metaimage_header() const {
    const auto& s = shape_.voxel_size;
    const auto& o = shape_.origin;
    constexpr bool big = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
    return std::string("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = ") +
           (big ? "True" : "False") +
           "\nCompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = " + exact(in_mm(o[0])) + " " +
           exact(in_mm(o[1])) + " " + exact(in_mm(o[2])) +
           "\nCenterOfRotation = 0 0 0\nElementSpacing = " + exact(in_mm(s[0])) + " " + exact(in_mm(s[1])) + " " +
           exact(in_mm(s[2])) + "\nDimSize = " + std::to_string(shape_.dims[0]) + " " + std::to_string(shape_.dims[1]) +
           " " + std::to_string(shape_.dims[2]) + "\nElementType = " + element() + "\nElementDataFile = LOCAL\n";
  }

  std::string nrrd_header() const {
    const auto& s = shape_.voxel_size;
    const auto& o = shape_.origin;
    constexpr bool big = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
    const std::string unit = "\"" + shape_.unit + "\"";
    return "NRRD0004\n# written by ivol\ntype: " + element() +
           "\ndimension: 3\nspace dimension: 3\nsizes: " + std::to_string(shape_.dims[0]) + " " +
           std::to_string(shape_.dims[1]) + " " + std::to_string(shape_.dims[2]) + "\nspace directions: (" +
           exact(s[0]) + ",0,0) (0," + exact(s[1]) + ",0) (0,0," + exact(s[2]) +
           ")\nkinds: domain domain domain\nendian: " + (big ? "big" : "little") + "\nencoding: gzip\nspace origin: (" +
           exact(o[0]) + "," + exact(o[1]) + "," + exact(o[2]) + ")\nspace units: " + unit + " " + unit + " " + unit +
           "\n\n";
  }

  void put(const void* data, std::uint64_t size) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    for (std::uint64_t done = 0; done < size;) {
      const ssize_t n = ::write(fd_, p + done, size - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error(ErrorClass::Io, path_ + ": write failed: " + std::strerror(errno));
      done += static_cast<std::uint64_t>(n);
    }
  }

  void deflate_some(const void* data, std::uint64_t size, int flush) {
    std::vector<std::uint8_t> out(1 << 20);
    const auto* p = static_cast<const std::uint8_t*>(data);
    std::uint64_t given = 0;
    for (;;) {
      if (stream_.avail_in == 0 && given < size) {
        const auto chunk = static_cast<uInt>(std::min<std::uint64_t>(size - given, 1u << 30));
        stream_.next_in = const_cast<Bytef*>(p + given);
        stream_.avail_in = chunk;
        given += chunk;
      }
      stream_.next_out = out.data();
      stream_.avail_out = static_cast<uInt>(out.size());
      const int status = ::deflate(&stream_, given < size ? Z_NO_FLUSH : flush);
      put(out.data(), out.size() - stream_.avail_out);
      if (status == Z_STREAM_END) return;
      if (status != Z_OK && status != Z_BUF_ERROR)
        throw Error(ErrorClass::Io, path_ + ": zlib failed while compressing (" + std::to_string(status) + ")");
      if (flush == Z_NO_FLUSH && given == size && stream_.avail_in == 0 && stream_.avail_out != 0) return;
    }
  }

  std::string path_;
  DenseVolume shape_;
  StagedFile staged_;
  bool nrrd_;
  int fd_ = -1;
  z_stream stream_{};
  bool deflating_ = false;
  RowPosition at_;
};

}  // namespace

std::unique_ptr<SlabReader> open_itk_image_slabs(const std::string& path) {
  return std::make_unique<ItkImageSlabReader>(path);
}

std::unique_ptr<SlabWriter> create_itk_image_slabs(const std::string& path, const DenseVolume& shape) {
  return std::make_unique<ItkImageSlabWriter>(path, shape);
}

}  // namespace ivol::convert
