// Geometry and metadata in TIFF files, read from what ImageJ/Fiji, tifffile
// and OME write, and written so that they read it back (README "Geometry
// through the formats").
//
// Reading (the first page of the first file), the first that applies:
//   1. ivol's own metadata: tag 65369 (private, ASCII) holding a JSON object
//      with the keys of the .ivol metadata block that describe a dense volume
//      (voxel_size, origin, unit, value {quantity, unit}, provenance);
//   2. OME-XML in ImageDescription: the Pixels element's PhysicalSizeX/Y/Z
//      and PhysicalSize*Unit (OME's default unit is the micrometre); a
//      missing PhysicalSizeZ is taken as PhysicalSizeX, with a note;
//   3. an ImageJ description ("ImageJ=..." lines): unit=, spacing= (z), and
//      the XResolution/YResolution tags as pixels per unit (x, y); when unit=
//      is absent, ResolutionUnit centimetre or inch says the unit;
//      xorigin/yorigin/zorigin (ImageJ's origin, in pixels) give the origin;
//      unit=pixel (or none) means uncalibrated: no voxel size.
// An ImageJ hyperstack of several channels or frames, or an OME image of
// several channels or time points, is refused (Error(Malformed)): its pages
// are not the slices of one grey volume.
// A plain TIFF's resolution tags are not read: without ImageJ's or OME's
// convention they are usually a scanner's or screen's dots per inch.
//
// Writing: every page carries XResolution/YResolution (pixels per unit,
// ResolutionUnit none, centimetre for "cm"); the first page carries an
// ImageJ description (images, slices, unit, spacing, origin) and tag 65369.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "dense_volume.hpp"

typedef struct tiff TIFF;

namespace ivol::convert {

// From the reusable private range (65000-65535), one that neither libtiff
// nor tifffile gives a meaning (65420-65459 are Hamamatsu NDPI's, 65000-65003
// EER's, 65100-65112 and 65200 others').
constexpr std::uint32_t kIvolMetadataTag = 65369;

// Makes libtiff know tag 65369 (once per process; before TIFFOpen).
void register_ivol_tiff_tag();

// Fills shape's geometry, metadata and *_from notes from an open TIFF at its
// first page; `where` names the file in messages. Throws Error(Malformed) on
// unreadable ivol or OME metadata.
void read_tiff_metadata(TIFF* tif, const std::string& where, DenseVolume& shape);

// Sets the tags of page `index` (of `count`) of a volume of `shape`.
void write_tiff_metadata(TIFF* tif, const DenseVolume& shape, std::uint32_t index, std::uint32_t count);

// The parsers, exposed for the tests.
struct ImageJDescription {
  bool is_imagej = false;
  std::string unit;  // as written; empty when absent
  std::optional<double> spacing;
  std::array<std::optional<double>, 3> origin_pixels;  // xorigin, yorigin, zorigin
  double channels = 1, frames = 1;                     // a hyperstack has more than one
};
ImageJDescription parse_imagej_description(const std::string& text);
std::string imagej_description(const DenseVolume& shape, std::uint32_t slices);

struct OmePhysicalSize {
  bool is_ome = false;
  std::array<std::optional<double>, 3> size;  // PhysicalSizeX, Y, Z
  std::array<std::string, 3> unit;            // their units ("µm" when absent)
  double channels = 1, times = 1;             // SizeC, SizeT
};
// Throws Error(Malformed) for OME-XML that does not parse.
OmePhysicalSize parse_ome_xml(const std::string& text, const std::string& where);

}  // namespace ivol::convert
