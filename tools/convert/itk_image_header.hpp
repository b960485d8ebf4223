// The headers of ITK's and RTK's native image files: MetaImage (.mha with
// the samples after the header, .mhd naming a separate data file) and NRRD
// (.nrrd attached, .nhdr detached). Both are text headers in front of (or
// beside) a block of samples, raw or zlib/gzip-compressed; ivol reads them
// into one description, for volumes and for projection stacks.
//
// What is refused, with the file, the field and the value named: more than
// three dimensions or one component per voxel, a direction matrix that is
// not the identity (ivol's volumes and RTK's projection stacks are
// axis-aligned; a rotated grid cannot be stored without resampling), data
// split over several files (MetaImage LIST, NRRD "data file: LIST" or a
// pattern), encodings other than raw, zlib and gzip, and sizes that do not
// fit the data found.
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace ivol::convert {

enum class ImageElement { Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float32, Float64 };

std::size_t element_size(ImageElement element);
const char* element_name(ImageElement element);  // "uint16", "float32", ...

enum class ImageEncoding { Raw, Zlib, Gzip };

struct ImageHeader {
  std::string format;  // "MetaImage" or "NRRD", for messages
  std::string path;    // the header's file
  int dimensions = 3;
  std::array<std::uint64_t, 3> size{1, 1, 1};  // x (fastest), y, z; 1 past `dimensions`
  ImageElement element = ImageElement::UInt16;
  bool big_endian = false;
  ImageEncoding encoding = ImageEncoding::Raw;

  std::string data_path;         // the file holding the samples (the header's own when attached)
  std::uint64_t data_offset = 0;  // where the samples (or their compressed stream) start
  std::uint64_t compressed_bytes = 0;  // MetaImage CompressedDataSize; 0: up to the end of the file

  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  std::array<double, 3> origin{0.0, 0.0, 0.0};  // centre of the first voxel
  std::string unit;  // NRRD space units when all three agree; empty: the file does not say
  bool has_spacing = false;
  bool has_origin = false;
  std::string spacing_field;  // e.g. "MetaImage ElementSpacing", "NRRD space directions"
  std::string origin_field;

  std::uint64_t sample_count() const;  // checked: throws on overflow
  std::uint64_t data_bytes() const;    // sample_count() × element size, checked
};

// Reads a header by the file's extension (.mha .mhd .nrrd .nhdr).
ImageHeader read_image_header(const std::string& path);
ImageHeader read_metaimage_header(const std::string& path);
ImageHeader read_nrrd_header(const std::string& path);

// Whether the extension is one of ITK's image formats (lower case, with the dot).
bool is_itk_image_extension(const std::string& extension);

}  // namespace ivol::convert
