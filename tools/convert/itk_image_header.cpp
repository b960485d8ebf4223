#include "itk_image_header.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "ivol/error.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

// A header is a few hundred bytes; a "header" of megabytes is not one.
constexpr std::size_t kMaxHeaderBytes = 1 << 20;

[[noreturn]] void refuse(const ImageHeader& h, const std::string& what) {
  throw Error(ErrorClass::InvalidArgument, h.path + ": " + h.format + " " + what);
}

std::string trim(const std::string& s) {
  std::size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

double number(const ImageHeader& h, const std::string& field, const std::string& text) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !std::isfinite(value)) refuse(h, field + ": '" + text + "' is not a number");
  return value;
}

std::vector<double> numbers(const ImageHeader& h, const std::string& field, const std::string& text,
                            std::size_t count) {
  const std::vector<std::string> w = words(text);
  if (w.size() != count)
    refuse(h, field + ": '" + text + "' has " + std::to_string(w.size()) + " values, not " + std::to_string(count));
  std::vector<double> out;
  for (const std::string& item : w) out.push_back(number(h, field, item));
  return out;
}

std::uint64_t whole(const ImageHeader& h, const std::string& field, const std::string& text, double least) {
  const double v = number(h, field, text);
  if (v < least || v != std::floor(v) || v > 9.0e15) refuse(h, field + ": '" + text + "' is not a valid count");
  return static_cast<std::uint64_t>(v);
}

void set_sizes(ImageHeader& h, const std::string& field, const std::string& text) {
  const std::vector<double> sizes = numbers(h, field, text, static_cast<std::size_t>(h.dimensions));
  for (int a = 0; a < h.dimensions; ++a) {
    if (sizes[a] < 1 || sizes[a] != std::floor(sizes[a]) || sizes[a] > 4294967295.0)
      refuse(h, field + ": '" + text + "' is not a list of positive sizes below 2^32");
    h.size[a] = static_cast<std::uint64_t>(sizes[a]);
  }
}

void set_dimensions(ImageHeader& h, const std::string& field, const std::string& text) {
  const std::uint64_t n = whole(h, field, text, 1);
  if (n < 2 || n > 3)
    refuse(h, field + ": " + text + " dimensions; ivol reads 2-D images and 3-D volumes or projection stacks");
  h.dimensions = static_cast<int>(n);
}

// The direction (rows: the axes' unit vectors) must be the identity.
void require_identity(const ImageHeader& h, const std::string& field, const std::vector<double>& m, int n) {
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) {
      const double expected = r == c ? 1.0 : 0.0;
      if (std::abs(m[static_cast<std::size_t>(r * n + c)] - expected) > 1e-9) {
        std::string text;
        for (double v : m) {
          char number_text[32];
          std::snprintf(number_text, sizeof number_text, "%g", v);
          text += (text.empty() ? "" : " ") + std::string(number_text);
        }
        refuse(h, field + " is " + text +
                      ", not the identity: ivol stores axis-aligned grids, and a rotated or flipped one cannot be "
                      "kept without resampling (resample it to the identity direction first)");
      }
    }
}

std::string sibling(const std::string& header_path, const std::string& name) {
  const std::filesystem::path p(name);
  if (p.is_absolute()) return name;
  return (std::filesystem::path(header_path).parent_path() / p).string();
}

std::uint64_t file_size_of(const ImageHeader& h, const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw Error(ErrorClass::Io, h.path + ": " + h.format + " data file " + path + ": " + ec.message());
  return size;
}

// The header's lines, up to `stop` (returns true to stop after that line);
// `end` is set to the offset after the last line read. Read a byte at a
// time up to 1 MiB, so that a "line" of gigabytes is never held.
template <typename Stop>
void read_lines(const ImageHeader& h, std::ifstream& in, Stop stop, std::uint64_t& end) {
  end = static_cast<std::uint64_t>(std::max<std::streamoff>(in.tellg(), 0));
  std::string line;
  for (int c; (c = in.get()) != EOF;) {
    if (++end > kMaxHeaderBytes) refuse(h, "header: longer than 1 MiB without its end");
    if (c != '\n') {
      line.push_back(static_cast<char>(c));
      continue;
    }
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (stop(line)) return;
    line.clear();
  }
  if (!line.empty()) stop(line);
}

ImageElement metaimage_element(const ImageHeader& h, const std::string& value) {
  static const std::pair<const char*, ImageElement> kTypes[] = {
      {"MET_CHAR", ImageElement::Int8},           {"MET_UCHAR", ImageElement::UInt8},
      {"MET_SHORT", ImageElement::Int16},         {"MET_USHORT", ImageElement::UInt16},
      {"MET_INT", ImageElement::Int32},           {"MET_UINT", ImageElement::UInt32},
      {"MET_LONG", ImageElement::Int32},          {"MET_ULONG", ImageElement::UInt32},
      {"MET_LONG_LONG", ImageElement::Int64},     {"MET_ULONG_LONG", ImageElement::UInt64},
      {"MET_FLOAT", ImageElement::Float32},       {"MET_DOUBLE", ImageElement::Float64}};
  for (const auto& [name, element] : kTypes)
    if (value == name) return element;
  refuse(h, "ElementType: '" + value + "' is not a scalar type ivol reads");
}

ImageElement nrrd_element(const ImageHeader& h, const std::string& value) {
  const std::string t = lower(value);
  if (t == "signed char" || t == "int8" || t == "int8_t") return ImageElement::Int8;
  if (t == "uchar" || t == "unsigned char" || t == "uint8" || t == "uint8_t") return ImageElement::UInt8;
  if (t == "short" || t == "short int" || t == "signed short" || t == "signed short int" || t == "int16" ||
      t == "int16_t")
    return ImageElement::Int16;
  if (t == "ushort" || t == "unsigned short" || t == "unsigned short int" || t == "uint16" || t == "uint16_t")
    return ImageElement::UInt16;
  if (t == "int" || t == "signed int" || t == "int32" || t == "int32_t") return ImageElement::Int32;
  if (t == "uint" || t == "unsigned int" || t == "uint32" || t == "uint32_t") return ImageElement::UInt32;
  if (t == "longlong" || t == "long long" || t == "long long int" || t == "signed long long" ||
      t == "signed long long int" || t == "int64" || t == "int64_t")
    return ImageElement::Int64;
  if (t == "ulonglong" || t == "unsigned long long" || t == "unsigned long long int" || t == "uint64" ||
      t == "uint64_t")
    return ImageElement::UInt64;
  if (t == "float") return ImageElement::Float32;
  if (t == "double") return ImageElement::Float64;
  refuse(h, "type: '" + value + "' is not a scalar type ivol reads");
}

bool truth(const std::string& value) {
  const std::string v = lower(value);
  return v == "true" || v == "1" || v == "yes";
}

// "(a,b,c)" → three numbers.
std::vector<double> vector_of(const ImageHeader& h, const std::string& field, const std::string& text,
                              std::size_t count) {
  std::string t = trim(text);
  if (t.size() < 2 || t.front() != '(' || t.back() != ')') refuse(h, field + ": '" + text + "' is not a (x,y,z) vector");
  t = t.substr(1, t.size() - 2);
  std::replace(t.begin(), t.end(), ',', ' ');
  return numbers(h, field, t, count);
}

void finish(ImageHeader& h) {
  if (h.dimensions == 2) h.size[2] = 1;
  h.data_bytes();  // checks the sizes' product
}

}  // namespace

std::size_t element_size(ImageElement element) {
  switch (element) {
    case ImageElement::Int8:
    case ImageElement::UInt8:
      return 1;
    case ImageElement::Int16:
    case ImageElement::UInt16:
      return 2;
    case ImageElement::Int32:
    case ImageElement::UInt32:
    case ImageElement::Float32:
      return 4;
    case ImageElement::Int64:
    case ImageElement::UInt64:
    case ImageElement::Float64:
      return 8;
  }
  return 1;
}

const char* element_name(ImageElement element) {
  switch (element) {
    case ImageElement::Int8:
      return "int8";
    case ImageElement::UInt8:
      return "uint8";
    case ImageElement::Int16:
      return "int16";
    case ImageElement::UInt16:
      return "uint16";
    case ImageElement::Int32:
      return "int32";
    case ImageElement::UInt32:
      return "uint32";
    case ImageElement::Int64:
      return "int64";
    case ImageElement::UInt64:
      return "uint64";
    case ImageElement::Float32:
      return "float32";
    case ImageElement::Float64:
      return "float64";
  }
  return "?";
}

std::uint64_t ImageHeader::sample_count() const {
  const std::string what = path + ": " + format + " sizes";
  return checked_mul(checked_mul(size[0], size[1], what), size[2], what);
}

std::uint64_t ImageHeader::data_bytes() const {
  return checked_mul(sample_count(), element_size(element), path + ": " + format + " sizes");
}

bool is_itk_image_extension(const std::string& extension) {
  return extension == ".mha" || extension == ".mhd" || extension == ".nrrd" || extension == ".nhdr";
}

ImageHeader read_metaimage_header(const std::string& path) {
  ImageHeader h;
  h.format = "MetaImage";
  h.path = path;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorClass::Io, path + ": cannot open");
  bool have_dims = false, have_type = false, have_data_file = false, binary = true;
  std::string data_file, size_text;
  std::int64_t header_size = 0;
  std::uint64_t end = 0;
  read_lines(
      h, in,
      [&](const std::string& line) {
        const std::size_t eq = line.find('=');
        if (eq == std::string::npos) {
          if (trim(line).empty()) return false;
          refuse(h, "header: '" + line.substr(0, 80) + "' is not a 'Key = Value' line");
        }
        const std::string key = trim(line.substr(0, eq));
        const std::string value = trim(line.substr(eq + 1));
        const std::string k = lower(key);
        if (k == "objecttype") {
          if (lower(value) != "image") refuse(h, "ObjectType: '" + value + "', not Image");
        } else if (k == "ndims") {
          set_dimensions(h, key, value);
        } else if (k == "dimsize") {
          size_text = value;
          have_dims = true;
        } else if (k == "elementtype") {
          h.element = metaimage_element(h, value);
          have_type = true;
        } else if (k == "elementnumberofchannels") {
          if (whole(h, key, value, 1) != 1) refuse(h, key + ": " + value + " components per voxel; ivol reads one");
        } else if (k == "binarydata") {
          binary = truth(value);
        } else if (k == "binarydatabyteordermsb" || k == "elementbyteordermsb") {
          h.big_endian = truth(value);
        } else if (k == "compresseddata") {
          h.encoding = truth(value) ? ImageEncoding::Zlib : ImageEncoding::Raw;
        } else if (k == "compresseddatasize") {
          h.compressed_bytes = whole(h, key, value, 0);
        } else if (k == "headersize") {
          const double v = number(h, key, value);
          if (v != std::floor(v) || v < -1 || v > 9.0e15) refuse(h, key + ": '" + value + "' is not a size or -1");
          header_size = static_cast<std::int64_t>(v);
        } else if (k == "elementspacing" || (k == "elementsize" && !h.has_spacing)) {
          const auto v = numbers(h, key, value, static_cast<std::size_t>(h.dimensions));
          for (int a = 0; a < h.dimensions; ++a) h.spacing[a] = v[a];
          h.has_spacing = true;
          h.spacing_field = "MetaImage " + key;
        } else if (k == "offset" || k == "origin" || k == "position") {
          const auto v = numbers(h, key, value, static_cast<std::size_t>(h.dimensions));
          for (int a = 0; a < h.dimensions; ++a) h.origin[a] = v[a];
          h.has_origin = true;
          h.origin_field = "MetaImage " + key;
        } else if (k == "transformmatrix" || k == "rotation" || k == "orientation" || k == "direction") {
          const auto n = static_cast<std::size_t>(h.dimensions);
          require_identity(h, key, numbers(h, key, value, n * n), h.dimensions);
        } else if (k == "elementdatafile") {
          data_file = value;
          have_data_file = true;
          return true;  // the samples follow this line
        }
        return false;
      },
      end);
  if (!have_data_file) refuse(h, "header: no ElementDataFile line (it ends the header)");
  if (!have_dims) refuse(h, "header: no DimSize");
  if (!have_type) refuse(h, "header: no ElementType");
  if (!binary) refuse(h, "BinaryData: False (text samples) is not read; write the image with binary data");
  set_sizes(h, "DimSize", size_text);
  finish(h);
  if (data_file == "LOCAL" || data_file == "Local" || data_file == "local") {
    h.data_path = path;
    h.data_offset = end;
  } else if (data_file.rfind("LIST", 0) == 0 || data_file.find('%') != std::string::npos) {
    refuse(h, "ElementDataFile: '" + data_file + "': samples split over several files are not read");
  } else {
    h.data_path = sibling(path, data_file);
    if (header_size == -1) {
      if (h.encoding != ImageEncoding::Raw) refuse(h, "HeaderSize: -1 is defined for uncompressed data only");
      const std::uint64_t size = file_size_of(h, h.data_path);
      if (size < h.data_bytes())
        refuse(h, "data file " + h.data_path + " has " + std::to_string(size) + " bytes, fewer than the " +
                      std::to_string(h.data_bytes()) + " its samples need");
      h.data_offset = size - h.data_bytes();
    } else {
      h.data_offset = static_cast<std::uint64_t>(header_size);
    }
  }
  return h;
}

ImageHeader read_nrrd_header(const std::string& path) {
  ImageHeader h;
  h.format = "NRRD";
  h.path = path;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorClass::Io, path + ": cannot open");
  std::string magic;
  std::getline(in, magic);
  if (magic.rfind("NRRD000", 0) != 0) refuse(h, "header: the file does not start with NRRD000x");
  bool have_dims = false, have_type = false, have_sizes = false, have_directions = false;
  std::string sizes_text, directions_text, spacings_text, data_file;
  std::int64_t byte_skip = 0;
  std::uint64_t line_skip = 0, end = 0;
  std::vector<std::string> units;
  read_lines(
      h, in,
      [&](const std::string& line) {
        if (line.empty()) return true;  // the samples follow the blank line
        if (line[0] == '#') return false;
        if (line.find(":=") != std::string::npos && line.find(": ") == std::string::npos) return false;  // key/value
        const std::size_t colon = line.find(": ");
        if (colon == std::string::npos) refuse(h, "header: '" + line.substr(0, 80) + "' is not a 'field: value' line");
        const std::string field = lower(trim(line.substr(0, colon)));
        const std::string value = trim(line.substr(colon + 2));
        if (field == "dimension") {
          set_dimensions(h, field, value);
          have_dims = true;
        } else if (field == "type") {
          h.element = nrrd_element(h, value);
          have_type = true;
        } else if (field == "sizes") {
          sizes_text = value;
          have_sizes = true;
        } else if (field == "encoding") {
          const std::string e = lower(value);
          if (e == "raw")
            h.encoding = ImageEncoding::Raw;
          else if (e == "gzip" || e == "gz")
            h.encoding = ImageEncoding::Gzip;
          else
            refuse(h, "encoding: '" + value + "' is not read (raw and gzip are)");
        } else if (field == "endian") {
          h.big_endian = lower(value) == "big";
        } else if (field == "space directions") {
          directions_text = value;
          have_directions = true;
        } else if (field == "spacings") {
          spacings_text = value;
        } else if (field == "space origin") {
          const auto v = vector_of(h, field, value, 3);
          for (int a = 0; a < 3; ++a) h.origin[a] = v[a];
          h.has_origin = true;
          h.origin_field = "NRRD space origin";
        } else if (field == "space units") {
          std::string unit;
          for (const std::string& w : words(value)) {
            std::string u = w;
            u.erase(std::remove(u.begin(), u.end(), '"'), u.end());
            units.push_back(u);
          }
        } else if (field == "data file" || field == "datafile") {
          data_file = value;
        } else if (field == "byte skip") {
          const double v = number(h, field, value);
          if (v != std::floor(v) || v < -1 || v > 9.0e15) refuse(h, "byte skip: '" + value + "' is not a size or -1");
          byte_skip = static_cast<std::int64_t>(v);
        } else if (field == "line skip") {
          line_skip = whole(h, field, value, 0);
        }
        return false;
      },
      end);
  if (!have_dims) refuse(h, "header: no dimension field");
  if (!have_type) refuse(h, "header: no type field");
  if (!have_sizes) refuse(h, "header: no sizes field");
  set_sizes(h, "sizes", sizes_text);
  finish(h);
  const int n = h.dimensions;
  if (have_directions) {
    // One vector per axis; "none" for an axis that is not in space.
    std::vector<double> m;
    std::istringstream list(directions_text);
    std::vector<std::string> vectors;
    for (std::string w; list >> w;) vectors.push_back(w);
    if (vectors.size() != static_cast<std::size_t>(n))
      refuse(h, "space directions: '" + directions_text + "' has " + std::to_string(vectors.size()) +
                    " vectors for " + std::to_string(n) + " axes");
    for (int a = 0; a < n; ++a) {
      const auto v = vector_of(h, "space directions", vectors[a], static_cast<std::size_t>(n));
      const double length = std::sqrt(v[0] * v[0] + v[1] * v[1] + (n == 3 ? v[2] * v[2] : 0.0));
      if (!(length > 0)) refuse(h, "space directions: axis " + std::to_string(a) + " has length 0");
      for (double c : v) m.push_back(c / length);
      h.spacing[a] = length;
    }
    require_identity(h, "space directions", m, n);
    h.has_spacing = true;
    h.spacing_field = "NRRD space directions";
  } else if (!spacings_text.empty()) {
    const auto v = numbers(h, "spacings", spacings_text, static_cast<std::size_t>(n));
    for (int a = 0; a < n; ++a)
      if (v[a] > 0) h.spacing[a] = v[a];
    h.has_spacing = true;
    h.spacing_field = "NRRD spacings";
  }
  if (!units.empty() && std::all_of(units.begin(), units.end(), [&](const std::string& u) { return u == units[0]; }))
    h.unit = units[0];
  if (data_file.empty()) {
    if (path.size() >= 5 && lower(path.substr(path.size() - 5)) == ".nhdr")
      refuse(h, "header: a detached header (.nhdr) without a data file field");
    h.data_path = path;
    h.data_offset = end;
  } else {
    if (lower(data_file).rfind("list", 0) == 0 || data_file.find('%') != std::string::npos ||
        words(data_file).size() > 1)
      refuse(h, "data file: '" + data_file + "': samples split over several files are not read");
    h.data_path = sibling(path, data_file);
    h.data_offset = 0;
  }
  if (line_skip > 0) {
    if (h.data_path == path) refuse(h, "line skip: only read with a separate data file");
    std::ifstream data(h.data_path, std::ios::binary);
    std::string skipped;
    for (std::uint64_t i = 0; i < line_skip; ++i)
      if (!std::getline(data, skipped)) refuse(h, "line skip: the data file has fewer than " + std::to_string(line_skip) + " lines");
    h.data_offset = static_cast<std::uint64_t>(data.tellg());
  }
  if (byte_skip == -1) {
    if (h.encoding != ImageEncoding::Raw) refuse(h, "byte skip: -1 is defined for raw data only");
    const std::uint64_t size = file_size_of(h, h.data_path);
    if (size < h.data_bytes())
      refuse(h, "data file " + h.data_path + " has " + std::to_string(size) + " bytes, fewer than the " +
                    std::to_string(h.data_bytes()) + " its samples need");
    h.data_offset = size - h.data_bytes();
  } else if (byte_skip > 0) {
    if (h.encoding != ImageEncoding::Raw) refuse(h, "byte skip inside compressed data is not read");
    h.data_offset += static_cast<std::uint64_t>(byte_skip);
  }
  return h;
}

ImageHeader read_image_header(const std::string& path) {
  const std::string e = lower(std::filesystem::path(path).extension().string());
  if (e == ".mha" || e == ".mhd") return read_metaimage_header(path);
  if (e == ".nrrd" || e == ".nhdr") return read_nrrd_header(path);
  throw Error(ErrorClass::InvalidArgument, path + ": not a MetaImage (.mha, .mhd) or NRRD (.nrrd, .nhdr) file");
}

}  // namespace ivol::convert
