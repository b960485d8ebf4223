// Projection stacks in ITK's native image files, as RTK writes them
// (rtkprojections, rtksimulatedgeometry + rtkprojectgeometricphantom): a 3-D
// image of columns (u, fastest), rows (v) and views, whose spacing is the
// detector pitch and whose origin is the position of the first pixel on the
// detector (RTK's projection origin).
#include <algorithm>
#include <cstring>
#include <memory>

#include "itk_image_header.hpp"
#include "itk_image_samples.hpp"
#include "ivol/error.hpp"
#include "projection_io.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

// Any stored type as double: exact for every 8-, 16- and 32-bit type.
void to_doubles(const std::uint8_t* bytes, std::size_t count, ImageElement element, double* out) {
  auto as = [&](auto zero) {
    using T = decltype(zero);
    for (std::size_t i = 0; i < count; ++i) {
      T v;
      std::memcpy(&v, bytes + i * sizeof(T), sizeof(T));
      out[i] = static_cast<double>(v);
    }
  };
  switch (element) {
    case ImageElement::Int8: as(std::int8_t{}); break;
    case ImageElement::UInt8: as(std::uint8_t{}); break;
    case ImageElement::Int16: as(std::int16_t{}); break;
    case ImageElement::UInt16: as(std::uint16_t{}); break;
    case ImageElement::Int32: as(std::int32_t{}); break;
    case ImageElement::UInt32: as(std::uint32_t{}); break;
    case ImageElement::Int64: as(std::int64_t{}); break;
    case ImageElement::UInt64: as(std::uint64_t{}); break;
    case ImageElement::Float32: as(float{}); break;
    case ImageElement::Float64: as(double{}); break;
  }
}

bool is_integer(ImageElement e) { return e != ImageElement::Float32 && e != ImageElement::Float64; }

void check_detector(const ImageHeader& h) {
  if (h.size[0] > 65536 || h.size[1] > 65536 || h.size[0] * h.size[1] > kMaxDetectorPixels)
    throw Error(ErrorClass::LimitExceeded, h.path + ": a detector of " + std::to_string(h.size[0]) + "x" +
                                               std::to_string(h.size[1]) + " pixels is larger than ivol reads");
}

class ItkImageProjections final : public ProjectionReader {
 public:
  explicit ItkImageProjections(const ImageHeader& header)
      : ProjectionReader(header.path, static_cast<int>(header.size[0]), static_cast<int>(header.size[1]),
                         static_cast<std::size_t>(header.size[2])),
        samples_(header) {
    // Reconstruction reads bands of rows of every view in turn: compressed
    // data are inflated once, not once per band.
    samples_.inflate_to_file();
  }
  void enable_intensities(const IntensityOptions& options, std::vector<double> flat, std::vector<double> dark) {
    set_fields(std::move(flat), std::move(dark), options);
  }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    const std::uint64_t columns = static_cast<std::uint64_t>(columns_);
    const std::uint64_t first = (std::uint64_t{view} * static_cast<std::uint64_t>(rows_) +
                                 static_cast<std::uint64_t>(row_begin)) * columns;
    const std::size_t count = static_cast<std::size_t>(row_end - row_begin) * static_cast<std::size_t>(columns);
    bytes_.resize(count * element_size(samples_.header().element));
    samples_.read(first, count, bytes_.data());
    to_doubles(bytes_.data(), count, samples_.header().element, out);
  }

 private:
  ImageSamples samples_;
  std::vector<std::uint8_t> bytes_;
};

// The mean image of flat or dark field files (each one image or a stack).
std::vector<double> field_of(const std::vector<std::string>& paths, const ImageHeader& scan, const char* kind) {
  const std::size_t pixels = static_cast<std::size_t>(scan.size[0] * scan.size[1]);
  FieldAverage average(pixels);
  std::vector<std::uint8_t> bytes;
  std::vector<double> image(pixels);
  for (const std::string& path : paths) {
    ImageSamples samples(read_image_header(path));
    const ImageHeader& h = samples.header();
    if (h.size[0] != scan.size[0] || h.size[1] != scan.size[1])
      throw Error(ErrorClass::InvalidArgument, path + ": " + kind + " field images are " + std::to_string(h.size[0]) +
                                                   "x" + std::to_string(h.size[1]) + ", the projections " +
                                                   std::to_string(scan.size[0]) + "x" + std::to_string(scan.size[1]));
    bytes.resize(pixels * element_size(h.element));
    for (std::uint64_t k = 0; k < h.size[2]; ++k) {
      samples.read(k * pixels, pixels, bytes.data());
      to_doubles(bytes.data(), pixels, h.element, image.data());
      average.add(image.data());
    }
  }
  return average.mean();
}

}  // namespace

ItkImageScan open_itk_image_projections(const std::string& path, StoredQuantity quantity,
                                        const IntensityOptions& intensity) {
  const ImageHeader header = read_image_header(path);
  if (header.dimensions != 3)
    throw Error(ErrorClass::InvalidArgument,
                path + ": a " + header.format + " image of 2 dimensions is one projection; a scan is a 3-D stack "
                       "(columns, rows, views)");
  check_detector(header);
  auto reader = std::make_unique<ItkImageProjections>(header);
  const bool intensities = is_integer(header.element) || quantity == StoredQuantity::Intensities;
  if (!intensities && (!intensity.flat_paths.empty() || !intensity.dark_paths.empty()))
    throw Error(ErrorClass::InvalidArgument, path + ": flat or dark fields given for line integrals");
  if (intensities)
    reader->enable_intensities(intensity, field_of(intensity.flat_paths, header, "flat"),
                               field_of(intensity.dark_paths, header, "dark"));
  ItkImageScan scan;
  scan.projections = std::move(reader);
  scan.has_pitch = header.has_spacing;
  scan.pitch = {header.spacing[0], header.spacing[1]};
  scan.pitch_field = header.spacing_field;
  scan.has_origin = header.has_origin;
  scan.origin = {header.origin[0], header.origin[1]};
  scan.origin_field = header.origin_field;
  scan.unit = header.unit;
  return scan;
}

}  // namespace ivol::convert
