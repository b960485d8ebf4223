#include "tiff_metadata.hpp"

#include <tiffio.h>

#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <pugixml.hpp>
#include <sstream>

#include "ivol/error.hpp"
#include "volume_metadata.hpp"

namespace ivol::convert {
namespace {

const TIFFFieldInfo kIvolField[] = {
    {kIvolMetadataTag, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0, const_cast<char*>("IvolMetadata")},
};

TIFFExtendProc parent_extender = nullptr;

void extend_tags(TIFF* tif) {
  TIFFMergeFieldInfo(tif, kIvolField, 1);
  if (parent_extender) parent_extender(tif);
}

std::string trim(const std::string& text) {
  const std::size_t b = text.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  return text.substr(b, text.find_last_not_of(" \t\r") + 1 - b);
}

std::optional<double> parse_number(const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used != text.size() || !std::isfinite(v)) return std::nullopt;
    return v;
  } catch (const std::logic_error&) {
    return std::nullopt;
  }
}

// Shortest text that reads back as the same double.
std::string number_text(double v) {
  for (int digits = 6; digits <= 17; ++digits) {
    std::ostringstream out;
    out.precision(digits);
    out << v;
    if (std::stod(out.str()) == v) return out.str();
  }
  return std::to_string(v);
}

// A rational tag holds about 7 significant digits (libtiff keeps a float):
// 1 / 33.333332 should read as 0.03, not 0.030000001.
double from_resolution(float pixels_per_unit) {
  const double size = 1.0 / static_cast<double>(pixels_per_unit);
  const double scale = std::pow(10.0, 6 - static_cast<int>(std::floor(std::log10(size))));
  return std::round(size * scale) / scale;
}

bool read_resolution(TIFF* tif, std::array<double, 3>& size) {
  float x = 0, y = 0;
  if (!TIFFGetField(tif, TIFFTAG_XRESOLUTION, &x) || !TIFFGetField(tif, TIFFTAG_YRESOLUTION, &y)) return false;
  if (!(x > 0) || !(y > 0) || !std::isfinite(x) || !std::isfinite(y)) return false;
  size[0] = from_resolution(x);
  size[1] = from_resolution(y);
  return true;
}

bool read_ivol_tag(TIFF* tif, const std::string& where, DenseVolume& shape) {
  const char* text = nullptr;
  if (!TIFFGetField(tif, kIvolMetadataTag, &text) || !text) return false;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(ErrorClass::Malformed,
                where + ": tag " + std::to_string(kIvolMetadataTag) + " is not ivol metadata JSON (" + e.what() + ")");
  }
  apply_metadata_json(j, where + ": tag " + std::to_string(kIvolMetadataTag), shape);
  const std::string from = "ivol metadata in the TIFF (tag " + std::to_string(kIvolMetadataTag) + ")";
  if (shape.has_geometry) shape.voxel_size_from = shape.origin_from = shape.unit_from = from;
  if (!shape.quantity.empty() || !shape.value_unit.empty()) shape.quantity_from = from;
  return true;
}

bool read_ome(const std::string& description, const std::string& where, DenseVolume& shape) {
  const OmePhysicalSize ome = parse_ome_xml(description, where);
  if (ome.channels > 1 || ome.times > 1)
    throw Error(ErrorClass::Malformed, where + ": an OME image of " + number_text(ome.channels) + " channels and " +
                                           number_text(ome.times) + " time points, not one grey volume");
  if (!ome.is_ome || !ome.size[0]) return ome.is_ome;
  const std::string unit = normalise_length_unit(ome.unit[0]);
  std::array<double, 3> size{};
  std::string note;
  for (int a = 0; a < 3; ++a) {
    std::optional<double> v = ome.size[a];
    std::string axis_unit = normalise_length_unit(ome.unit[a]);
    if (!v) {  // a 2-D OME image says nothing of z (or y): take x's
      v = ome.size[0];
      axis_unit = unit;
      note += std::string(note.empty() ? "" : ", ") + "PhysicalSize" + "XYZ"[a] + " absent: taken as PhysicalSizeX";
    }
    const double factor = length_unit_factor(axis_unit, unit);
    if (!(factor > 0))
      throw Error(ErrorClass::Malformed, where + ": OME PhysicalSize" + std::string(1, "XYZ"[a]) + "Unit '" +
                                             ome.unit[a] + "' cannot be converted to PhysicalSizeXUnit '" +
                                             ome.unit[0] + "'");
    size[a] = *v * factor;
    if (!(size[a] > 0) || !std::isfinite(size[a]))
      throw Error(ErrorClass::Malformed,
                  where + ": OME PhysicalSize" + std::string(1, "XYZ"[a]) + " must be positive and finite");
  }
  shape.voxel_size = size;
  shape.unit = unit.empty() ? "um" : unit;
  shape.has_geometry = true;
  shape.voxel_size_from = "OME-TIFF PhysicalSize" + (note.empty() ? std::string() : "; " + note);
  shape.unit_from = "OME-TIFF PhysicalSizeXUnit";
  return true;
}

bool read_imagej(TIFF* tif, const std::string& description, const std::string& where, DenseVolume& shape) {
  const ImageJDescription ij = parse_imagej_description(description);
  if (!ij.is_imagej) return false;
  if (ij.channels > 1 || ij.frames > 1)
    throw Error(ErrorClass::Malformed, where + ": an ImageJ hyperstack of " + number_text(ij.channels) +
                                           " channels and " + number_text(ij.frames) +
                                           " frames, not one grey volume; split it first (Fiji: Image > Stacks > "
                                           "Tools > Reduce Dimensionality, or Image > Color > Split Channels)");
  std::string unit = normalise_length_unit(ij.unit);
  std::string unit_from = "ImageJ unit=";
  std::uint16_t resolution_unit = RESUNIT_NONE;
  TIFFGetFieldDefaulted(tif, TIFFTAG_RESOLUTIONUNIT, &resolution_unit);
  double factor = 1.0;
  if (unit.empty() && resolution_unit == RESUNIT_CENTIMETER) unit = "cm", unit_from = "TIFF ResolutionUnit";
  if (unit.empty() && resolution_unit == RESUNIT_INCH) unit = "mm", factor = 25.4, unit_from = "TIFF ResolutionUnit";
  std::array<double, 3> size{};
  if (unit.empty() || !read_resolution(tif, size)) return true;  // uncalibrated
  size[0] *= factor;
  size[1] *= factor;
  std::string from = "ImageJ XResolution/YResolution";
  if (ij.spacing && *ij.spacing > 0 && std::isfinite(*ij.spacing * factor)) {
    size[2] = *ij.spacing * factor;
    from += " and spacing=";
  } else {
    size[2] = size[0];
    from += "; no spacing=: z taken as x";
  }
  shape.voxel_size = size;
  shape.unit = unit;
  shape.has_geometry = true;
  shape.voxel_size_from = from;
  shape.unit_from = unit_from;
  if (ij.origin_pixels[0] || ij.origin_pixels[1] || ij.origin_pixels[2]) {
    // ImageJ's calibrated x of pixel i is (i - xorigin) * pixelWidth.
    for (int a = 0; a < 3; ++a) {
      shape.origin[a] = -ij.origin_pixels[a].value_or(0.0) * size[a];
      if (!std::isfinite(shape.origin[a]))
        throw Error(ErrorClass::Malformed, where + ": ImageJ " + std::string(1, "xyz"[a]) + "origin is out of range");
    }
    shape.origin_from = "ImageJ xorigin/yorigin/zorigin";
  }
  return true;
}

}  // namespace

void register_ivol_tiff_tag() {
  static const bool once = [] {
    parent_extender = TIFFSetTagExtender(extend_tags);
    return true;
  }();
  (void)once;
}

ImageJDescription parse_imagej_description(const std::string& text) {
  ImageJDescription out;
  if (text.rfind("ImageJ=", 0) != 0) return out;
  out.is_imagej = true;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    const std::size_t eq = line.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = trim(line.substr(0, eq)), value = trim(line.substr(eq + 1));
    if (key == "unit") out.unit = value;
    if (key == "spacing") out.spacing = parse_number(value);
    if (key == "xorigin") out.origin_pixels[0] = parse_number(value);
    if (key == "yorigin") out.origin_pixels[1] = parse_number(value);
    if (key == "zorigin") out.origin_pixels[2] = parse_number(value);
    if (key == "channels") out.channels = parse_number(value).value_or(1);
    if (key == "frames") out.frames = parse_number(value).value_or(1);
  }
  return out;
}

std::string imagej_description(const DenseVolume& shape, std::uint32_t slices) {
  // What tifffile writes for a (slices, y, x) stack, plus the calibration.
  std::string text = "ImageJ=1.11a\nimages=" + std::to_string(slices) + "\n";
  if (slices > 1) text += "slices=" + std::to_string(slices) + "\n";
  if (shape.has_geometry) {
    // ImageJ reads the description as Latin-1: "um", not UTF-8 "µm".
    const std::string unit = normalise_length_unit(shape.unit);
    text += "unit=" + (unit.empty() ? "pixel" : unit) + "\nspacing=" + number_text(shape.voxel_size[2]) + "\n";
    if (shape.origin != std::array<double, 3>{0, 0, 0})
      for (int a = 0; a < 3; ++a)
        text += std::string(1, "xyz"[a]) + "origin=" + number_text(-shape.origin[a] / shape.voxel_size[a]) + "\n";
  }
  return text + "loop=false\n";
}

OmePhysicalSize parse_ome_xml(const std::string& text, const std::string& where) {
  OmePhysicalSize out;
  const std::size_t start = text.find_first_not_of(" \t\r\n");
  if (start == std::string::npos || text[start] != '<' || text.find("OME") == std::string::npos) return out;
  pugi::xml_document doc;
  const pugi::xml_parse_result parsed = doc.load_buffer(text.data(), text.size());
  if (!parsed) return out;  // an XML description that is not OME's
  auto local = [](const char* name) {
    const char* colon = std::strrchr(name, ':');
    return std::string(colon ? colon + 1 : name);
  };
  if (local(doc.document_element().name()) != "OME") return out;
  out.is_ome = true;
  pugi::xml_node pixels;
  for (pugi::xml_node image : doc.document_element().children()) {
    if (local(image.name()) != "Image") continue;
    for (pugi::xml_node child : image.children())
      if (local(child.name()) == "Pixels") {
        pixels = child;
        break;
      }
    if (pixels) break;
  }
  if (!pixels) return out;
  for (int a = 0; a < 3; ++a) {
    const std::string axis(1, "XYZ"[a]);
    const pugi::xml_attribute size = pixels.attribute(("PhysicalSize" + axis).c_str());
    if (size) {
      out.size[a] = parse_number(trim(size.value()));
      if (!out.size[a] || !(*out.size[a] > 0))
        throw Error(ErrorClass::Malformed,
                    where + ": OME PhysicalSize" + axis + " '" + size.value() + "' is not a positive number");
    }
    const pugi::xml_attribute unit = pixels.attribute(("PhysicalSize" + axis + "Unit").c_str());
    out.unit[a] = unit ? unit.value() : "\u00b5m";
  }
  if (const pugi::xml_attribute c = pixels.attribute("SizeC")) out.channels = parse_number(trim(c.value())).value_or(1);
  if (const pugi::xml_attribute t = pixels.attribute("SizeT")) out.times = parse_number(trim(t.value())).value_or(1);
  return out;
}

void read_tiff_metadata(TIFF* tif, const std::string& where, DenseVolume& shape) {
  if (read_ivol_tag(tif, where, shape)) return;
  const char* description = nullptr;
  if (!TIFFGetField(tif, TIFFTAG_IMAGEDESCRIPTION, &description) || !description) return;
  const std::string text(description);
  if (read_ome(text, where, shape)) return;
  read_imagej(tif, text, where, shape);
}

void write_tiff_metadata(TIFF* tif, const DenseVolume& shape, std::uint32_t index, std::uint32_t count) {
  if (shape.has_geometry) {
    TIFFSetField(tif, TIFFTAG_XRESOLUTION, 1.0 / shape.voxel_size[0]);
    TIFFSetField(tif, TIFFTAG_YRESOLUTION, 1.0 / shape.voxel_size[1]);
    TIFFSetField(tif, TIFFTAG_RESOLUTIONUNIT, shape.unit == "cm" ? RESUNIT_CENTIMETER : RESUNIT_NONE);
  }
  if (index != 0) return;
  TIFFSetField(tif, TIFFTAG_IMAGEDESCRIPTION, imagej_description(shape, count).c_str());
  // ensure_ascii: the tag is ASCII; JSON's \u escapes keep any text.
  const std::string json = metadata_json(shape).dump(-1, ' ', true);
  TIFFSetField(tif, kIvolMetadataTag, json.c_str());
}

}  // namespace ivol::convert
