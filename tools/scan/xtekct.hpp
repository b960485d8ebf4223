// Nikon XT scans: an .xtekct INI file (the scan's geometry, as Nikon's
// CT Pro writes it) next to a folder of TIFF projections, and optionally the
// measured angles in _ctdata.txt or NAME.ang. The keys and their meaning are
// those public readers use (the Core Imaging Library's NikonDataReader and
// its predecessors); docs/geometry.md states how each maps onto ivol's
// geometry. Lengths are millimetres, angles degrees.
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "projection_io.hpp"

namespace ivol::convert {

// The keys ivol reads, from the [XTekCT] section (or the whole file when it
// has no sections).
struct XtekctKeys {
  std::string name;          // Name: stem of the projection files NAME_0001.tif ...
  std::string input_folder;  // InputFolderName: the projections' folder
  std::uint64_t projections = 0;
  double white_level = 0.0;  // the unattenuated intensity
  int pixels_x = 0, pixels_y = 0;
  double pixel_size_x = 0.0, pixel_size_y = 0.0;
  double src_to_object = 0.0, src_to_detector = 0.0;
  double initial_angle = 0.0, angular_step = 0.0;
  std::optional<double> object_offset_x;  // mm at the rotation axis
  std::optional<double> object_roll;      // degrees
  double object_tilt = 0.0;               // degrees
  double centre_of_rotation_top = 0.0, centre_of_rotation_bottom = 0.0;
  double detector_offset_x = 0.0, detector_offset_y = 0.0;
  bool has_grid = false;  // VoxelsX/Y/Z and VoxelSizeX/Y/Z all given
  std::array<std::uint32_t, 3> voxels{0, 0, 0};
  std::array<double, 3> voxel_size{0.0, 0.0, 0.0};
};

// Parses the text of an .xtekct file; `path` names it in errors, which say
// the key and what is wrong with its value.
XtekctKeys parse_xtekct(const std::string& text, const std::string& path);

// Angles (degrees, in projection order) of a _ctdata.txt (header lines, then
// "index angle time" per projection) or an .ang file (a header line, then
// "index: angle" per projection), sorted by the index; `expected` lines of
// data are required.
std::vector<double> parse_ctdata_angles(const std::string& text, const std::string& path, std::uint64_t expected);
std::vector<double> parse_ang_angles(const std::string& text, const std::string& path, std::uint64_t expected);

// ivol's geometry of a scan with these keys and the angles φ (degrees) of
// its projections (InitialAngle included), and what each value came from.
struct XtekctGeometry {
  ivol::recon::ScanGeometry geometry;
  std::vector<std::pair<std::string, std::string>> mapping;  // ivol value, the keys it came from
};
XtekctGeometry xtekct_geometry(const XtekctKeys& keys, const std::vector<double>& angles_deg, const std::string& path);

// Reads and parses an .xtekct file.
XtekctKeys read_xtekct(const std::string& path);

// The files of a scan: its TIFF projections (FOLDER/NAME_*.tif, else every
// TIFF of FOLDER, in natural order; FOLDER is InputFolderName relative to
// the .xtekct file, or its last component, else the .xtekct file's own
// folder), and its angle file (_ctdata.txt, else NAME.ang, next to the
// .xtekct file; "" when there is none).
struct XtekctFiles {
  std::string source;  // the glob or folder the projections came from
  std::vector<std::string> projections;
  std::string angles;
  bool angles_are_ang = false;
};
XtekctFiles xtekct_files(const std::string& path, const XtekctKeys& keys);

struct XtekctScan {
  XtekctKeys keys;
  std::unique_ptr<ProjectionReader> projections;  // line integrals −log(I / WhiteLevel), rotated 180° (see .cpp)
  XtekctGeometry geometry;
  std::string projection_source;  // the folder or glob the TIFFs came from
  std::string angles_from;        // the file the angles came from, or "InitialAngle + i·AngularStep"
};

// Opens the scan the .xtekct file describes.
XtekctScan open_xtekct(const std::string& path);

}  // namespace ivol::convert
