// The line-integral conversion shared by the projection readers, and raw
// projection files.
#include "projection_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <utility>

#include "ivol/error.hpp"
#include "staged_file.hpp"

namespace ivol::convert {

ProjectionReader::ProjectionReader(std::string path, int columns, int rows, std::size_t views)
    : path_(std::move(path)), columns_(columns), rows_(rows), views_(views) {
  if (columns <= 0 || rows <= 0 || views == 0)
    throw Error(ErrorClass::InvalidArgument, path_ + ": the scan is empty (" + std::to_string(views) + " views of " +
                                                 std::to_string(columns) + "x" + std::to_string(rows) + " pixels)");
  // The per-pixel flat-field tables take 9 bytes a pixel before any data is
  // read, so a few hundred bytes of hostile header must not be able to ask
  // for gigabytes. 2^27 pixels (11585²) is above any CT detector made.
  const std::uint64_t pixels = std::uint64_t(columns) * std::uint64_t(rows);
  if (pixels > kMaxDetectorPixels)
    throw Error(ErrorClass::LimitExceeded, path_ + ": a detector of " + std::to_string(columns) + "x" +
                                               std::to_string(rows) + " pixels is larger than the " +
                                               std::to_string(kMaxDetectorPixels) + " pixels ivol reads");
}

ProjectionReader::~ProjectionReader() = default;

void ProjectionReader::set_fields(std::vector<double> flat, std::vector<double> dark, const IntensityOptions& options) {
  const std::size_t pixels = static_cast<std::size_t>(columns_) * static_cast<std::size_t>(rows_);
  if (!(options.minimum_signal > 0.0) || !std::isfinite(options.minimum_signal))
    throw Error(ErrorClass::InvalidArgument, path_ + ": the minimum signal must be positive and finite");
  if (flat.empty() && !(options.incident_intensity > 0.0 && std::isfinite(options.incident_intensity)))
    throw Error(ErrorClass::InvalidArgument,
                path_ + ": intensities need a flat field or a positive incident intensity to become line integrals");
  if ((!flat.empty() && flat.size() != pixels) || (!dark.empty() && dark.size() != pixels))
    throw Error(ErrorClass::InvalidArgument, path_ + ": flat or dark field of the wrong size");
  floor_ = options.minimum_signal;
  denominator_.assign(pixels, 0.0);
  bad_denominator_.assign(pixels, 0);
  for (std::size_t i = 0; i < pixels; ++i) {
    const double f = flat.empty() ? options.incident_intensity : flat[i];
    double d = f - (dark.empty() ? 0.0 : dark[i]);
    if (!(d >= floor_)) {
      d = floor_;
      bad_denominator_[i] = 1;
    }
    denominator_[i] = d;
  }
  dark_ = std::move(dark);
  intensities_ = true;
}

void ProjectionReader::read_rows(std::size_t view, int row_begin, int row_end, float* out) {
  if (view >= views_ || row_begin < 0 || row_end > rows_ || row_begin > row_end)
    throw Error(ErrorClass::InvalidArgument, path_ + ": rows " + std::to_string(row_begin) + ".." +
                                                 std::to_string(row_end) + " of view " + std::to_string(view) +
                                                 " are outside the scan (" + std::to_string(views_) + " views of " +
                                                 std::to_string(rows_) + " rows)");
  const std::size_t first = static_cast<std::size_t>(row_begin) * static_cast<std::size_t>(columns_);
  const std::size_t count = static_cast<std::size_t>(row_end - row_begin) * static_cast<std::size_t>(columns_);
  if (count == 0) return;
  scratch_.resize(count);
  read_samples(view, row_begin, row_end, scratch_.data());
  if (!intensities_) {
    for (std::size_t i = 0; i < count; ++i) out[i] = static_cast<float>(scratch_[i]);
    return;
  }
  std::uint64_t clamped = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t pixel = first + i;
    double numerator = scratch_[i] - (dark_.empty() ? 0.0 : dark_[pixel]);
    bool bad = bad_denominator_[pixel] != 0;
    if (!(numerator >= floor_)) {
      numerator = floor_;
      bad = true;
    }
    clamped += bad ? 1 : 0;
    out[i] = static_cast<float>(-std::log(numerator / denominator_[pixel]));
  }
  clamped_ += clamped;
}

void FieldAverage::add(const double* image) {
  for (std::size_t i = 0; i < sum_.size(); ++i) sum_[i] += image[i];
  ++count_;
}

std::vector<double> FieldAverage::mean() const {
  if (count_ == 0) return {};
  std::vector<double> m(sum_);
  for (double& x : m) x /= static_cast<double>(count_);
  return m;
}

namespace {

constexpr bool kBigEndianHost = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;

std::size_t sample_bytes(RawSampleType type) { return type == RawSampleType::UInt16 ? 2 : 4; }

void to_native(std::uint8_t* data, std::size_t bytes, std::size_t width) {
  if (!kBigEndianHost) return;
  for (std::size_t i = 0; i + width <= bytes; i += width)
    for (std::size_t a = 0, b = width - 1; a < b; ++a, --b) std::swap(data[i + a], data[i + b]);
}

void decode(const std::uint8_t* bytes, std::size_t count, RawSampleType type, double* out) {
  if (type == RawSampleType::UInt16) {
    for (std::size_t i = 0; i < count; ++i) {
      std::uint16_t v;
      std::memcpy(&v, bytes + 2 * i, 2);
      out[i] = v;
    }
  } else {
    for (std::size_t i = 0; i < count; ++i) {
      float v;
      std::memcpy(&v, bytes + 4 * i, 4);
      out[i] = v;
    }
  }
}

// A file descriptor closed on destruction.
class Fd {
 public:
  Fd(const std::string& path, int flags) : fd_(::open(path.c_str(), flags | O_CLOEXEC, 0644)) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }
  int release() { return std::exchange(fd_, -1); }

 private:
  int fd_;
};

// pread of exactly `size` bytes; false at end of file.
bool read_exactly(int fd, std::uint8_t* out, std::size_t size, std::uint64_t offset) {
  for (std::size_t done = 0; done < size;) {
    const ssize_t n = ::pread(fd, out + done, size - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(ErrorClass::Io, std::string("read failed: ") + std::strerror(errno));
    if (n == 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

std::uint64_t file_size(const std::string& path, int fd) {
  struct stat st {};
  if (fd < 0 || ::fstat(fd, &st) != 0) throw Error(ErrorClass::Io, path + ": cannot open: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) throw Error(ErrorClass::InvalidArgument, path + ": not a regular file");
  return static_cast<std::uint64_t>(st.st_size);
}

// Mean of the images of raw field files (flat or dark).
std::vector<double> raw_field(const std::vector<std::string>& paths, const RawProjectionLayout& layout,
                              const char* kind) {
  const std::size_t pixels = static_cast<std::size_t>(layout.columns) * static_cast<std::size_t>(layout.rows);
  const std::size_t image_bytes = pixels * sample_bytes(layout.sample);
  FieldAverage average(pixels);
  std::vector<std::uint8_t> bytes(image_bytes);
  std::vector<double> image(pixels);
  for (const std::string& path : paths) {
    Fd fd(path, O_RDONLY);
    const std::uint64_t size = file_size(path, fd.get());
    if (size < layout.header_bytes + image_bytes || (size - layout.header_bytes) % image_bytes != 0)
      throw Error(ErrorClass::InvalidArgument, path + ": " + kind + " field file has " + std::to_string(size) +
                                                   " bytes, not " + std::to_string(layout.header_bytes) +
                                                   " header bytes plus a whole number of " +
                                                   std::to_string(layout.columns) + "x" + std::to_string(layout.rows) +
                                                   " images of " + std::to_string(image_bytes) + " bytes");
    const std::uint64_t images = (size - layout.header_bytes) / image_bytes;
    for (std::uint64_t k = 0; k < images; ++k) {
      if (!read_exactly(fd.get(), bytes.data(), image_bytes, layout.header_bytes + k * image_bytes))
        throw Error(ErrorClass::Io, path + ": " + kind + " field image " + std::to_string(k) + " is cut short");
      to_native(bytes.data(), image_bytes, sample_bytes(layout.sample));
      decode(bytes.data(), pixels, layout.sample, image.data());
      average.add(image.data());
    }
  }
  return average.mean();
}

class RawProjections final : public ProjectionReader {
 public:
  RawProjections(const std::string& path, const RawProjectionLayout& layout, const IntensityOptions& intensity)
      : ProjectionReader(path, layout.columns, layout.rows, layout.views), layout_(layout), fd_(path, O_RDONLY) {
    const std::uint64_t size = file_size(path, fd_.get());
    const std::uint64_t expected =
        layout.header_bytes + std::uint64_t{layout.views} * layout.rows * layout.columns * sample_bytes(layout.sample);
    if (size != expected)
      throw Error(ErrorClass::InvalidArgument,
                  path + ": the file has " + std::to_string(size) + " bytes, but " + std::to_string(layout.views) +
                      " views x " + std::to_string(layout.rows) + " rows x " + std::to_string(layout.columns) +
                      " columns of " + (layout.sample == RawSampleType::UInt16 ? "uint16" : "float32") + " after " +
                      std::to_string(layout.header_bytes) + " header bytes need " + std::to_string(expected));
    const bool intensities = layout.sample == RawSampleType::UInt16 || layout.quantity == StoredQuantity::Intensities;
    if (!intensities && (!intensity.flat_paths.empty() || !intensity.dark_paths.empty()))
      throw Error(ErrorClass::InvalidArgument, path + ": flat or dark fields given for line integrals");
    if (intensities)
      set_fields(raw_field(intensity.flat_paths, layout, "flat"), raw_field(intensity.dark_paths, layout, "dark"),
                 intensity);
  }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    const std::size_t width = sample_bytes(layout_.sample);
    const std::size_t count = static_cast<std::size_t>(row_end - row_begin) * static_cast<std::size_t>(columns_);
    const std::uint64_t offset =
        layout_.header_bytes +
        ((std::uint64_t{view} * rows_ + static_cast<std::uint64_t>(row_begin)) * columns_) * width;
    bytes_.resize(count * width);
    bool complete = false;
    try {
      complete = read_exactly(fd_.get(), bytes_.data(), bytes_.size(), offset);
    } catch (const Error& e) {
      throw Error(ErrorClass::Io, where(view, row_begin, row_end) + ": " + e.what());
    }
    if (!complete)
      throw Error(ErrorClass::Io, where(view, row_begin, row_end) + ": the file was cut short after opening");
    to_native(bytes_.data(), bytes_.size(), width);
    decode(bytes_.data(), count, layout_.sample, out);
  }

 private:
  std::string where(std::size_t view, int row_begin, int row_end) const {
    return path_ + ": view " + std::to_string(view) + " rows " + std::to_string(row_begin) + ".." +
           std::to_string(row_end);
  }

  RawProjectionLayout layout_;
  Fd fd_;
  std::vector<std::uint8_t> bytes_;
};

}  // namespace

std::unique_ptr<ProjectionReader> open_raw_projections(const std::string& path, const RawProjectionLayout& layout,
                                                       const IntensityOptions& intensity) {
  return std::make_unique<RawProjections>(path, layout, intensity);
}

void write_raw_projections(const std::string& path, ivol::recon::ProjectionSource& source) {
  const std::size_t image = static_cast<std::size_t>(source.columns()) * static_cast<std::size_t>(source.rows());
  StagedFile staged(path);
  Fd fd(staged.temp_path(), O_WRONLY | O_TRUNC);
  if (fd.get() < 0) throw Error(ErrorClass::Io, path + ": cannot open a temporary file: " + std::strerror(errno));
  std::vector<float> values(image);
  for (std::size_t view = 0; view < source.view_count(); ++view) {
    source.read_rows(view, 0, source.rows(), values.data());
    auto* bytes = reinterpret_cast<std::uint8_t*>(values.data());
    to_native(bytes, image * 4, 4);  // native to little-endian: the same swap
    for (std::size_t done = 0; done < image * 4;) {
      const ssize_t n = ::write(fd.get(), bytes + done, image * 4 - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0)
        throw Error(ErrorClass::Io,
                    path + ": write failed at view " + std::to_string(view) + ": " + std::strerror(errno));
      done += static_cast<std::size_t>(n);
    }
  }
  if (::close(fd.release()) != 0)
    throw Error(ErrorClass::Io, path + ": cannot close the file: " + std::strerror(errno));
  staged.commit();
}

}  // namespace ivol::convert
