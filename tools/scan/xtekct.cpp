// Nikon XT scans (.xtekct + TIFF projections): the keys, the angle files and
// the mapping onto ivol's geometry.
//
// The frame public readers give these scans (CIL's NikonDataReader): the
// source at the origin, the beam along +y, the rotation axis vertical at
// x = −ObjectOffsetX, y = SrcToObject, the detector centred on x = 0 at
// y = SrcToDetector, its first pixel at the top right (columns run towards
// −x, rows downwards) and the object turned by 180° − φ for a projection
// taken at stage angle φ. In ivol's frame (geometry.hpp, the axis at the
// origin) that is: each image rotated by 180° (columns and rows reversed, so
// that the column index runs along û and the row index upwards), the source
// and the detector both shifted by +ObjectOffsetX along û, and the gantry at
// θ = φ − 180°.
#include "xtekct.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void bad(const std::string& path, const std::string& what) {
  throw Error(ErrorClass::InvalidArgument, path + ": " + what);
}

std::string trim(const std::string& s) {
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return {};
  return s.substr(first, s.find_last_not_of(" \t\r\n") - first + 1);
}

std::string number_text(double v) {
  std::ostringstream text;
  text.precision(9);
  text << v;
  return text.str();
}

// key → value of the [XTekCT] section (every key outside sections when the
// file has none). The first occurrence of a key counts.
std::map<std::string, std::string> section_keys(const std::string& text, const std::string& path) {
  std::map<std::string, std::string> in_section, outside;
  bool has_sections = false, in_xtekct = false;
  std::istringstream lines(text);
  std::string line;
  std::size_t count = 0;
  while (std::getline(lines, line)) {
    if (++count > 100000) bad(path, "more than 100000 lines: not an .xtekct file");
    line = trim(line);
    if (line.empty() || line[0] == ';' || line[0] == '#') continue;
    if (line[0] == '[') {
      has_sections = true;
      in_xtekct = line == "[XTekCT]";
      continue;
    }
    const auto equals = line.find('=');
    if (equals == std::string::npos) continue;
    auto& keys = has_sections ? in_section : outside;
    if (has_sections && !in_xtekct) continue;
    keys.emplace(trim(line.substr(0, equals)), trim(line.substr(equals + 1)));
  }
  if (has_sections && in_section.empty()) bad(path, "no [XTekCT] section");
  return has_sections ? in_section : outside;
}

class Keys {
 public:
  Keys(std::map<std::string, std::string> keys, std::string path) : keys_(std::move(keys)), path_(std::move(path)) {}

  bool has(const std::string& key) const { return keys_.count(key) && !keys_.at(key).empty(); }
  std::string text(const std::string& key) const { return has(key) ? keys_.at(key) : std::string(); }

  double number(const std::string& key) const {
    if (!has(key)) bad(path_, "key " + key + " is missing");
    const std::string& value = keys_.at(key);
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || trim(value.substr(used)) != "" || !std::isfinite(v))
      bad(path_, "key " + key + " is '" + value + "', not a number");
    return v;
  }
  double number(const std::string& key, double otherwise) const { return has(key) ? number(key) : otherwise; }
  std::optional<double> optional(const std::string& key) const {
    return has(key) ? std::optional<double>(number(key)) : std::nullopt;
  }
  double positive(const std::string& key) const {
    const double v = number(key);
    if (!(v > 0)) bad(path_, "key " + key + " is " + number_text(v) + "; it must be positive");
    return v;
  }
  std::uint64_t whole(const std::string& key, double most) const {
    const double v = number(key);
    if (!(v >= 1) || v != std::floor(v) || v > most)
      bad(path_, "key " + key + " is " + number_text(v) + ", not a whole number from 1 to " + number_text(most));
    return static_cast<std::uint64_t>(v);
  }

 private:
  std::map<std::string, std::string> keys_;
  std::string path_;
};

// Lines of two or more numbers: (index, angle). Lines that do not start
// with two numbers (headers) are skipped.
std::vector<double> indexed_angles(const std::string& text, const std::string& path, std::uint64_t expected,
                                   bool colon) {
  std::vector<std::pair<double, double>> rows;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    if (colon) std::replace(line.begin(), line.end(), ':', ' ');
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream fields(line);
    double index = 0, angle = 0;
    if (!(fields >> index >> angle) || !std::isfinite(index) || !std::isfinite(angle)) continue;
    if (rows.size() >= expected) bad(path, "lists more than the " + std::to_string(expected) + " projections");
    rows.emplace_back(index, angle);
  }
  if (rows.size() != expected)
    bad(path, "lists " + std::to_string(rows.size()) + " angles for " + std::to_string(expected) + " projections");
  std::stable_sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (std::size_t i = 1; i < rows.size(); ++i)
    if (rows[i].first == rows[i - 1].first) bad(path, "lists projection " + number_text(rows[i].first) + " twice");
  std::vector<double> angles;
  for (const auto& row : rows) angles.push_back(row.second);
  return angles;
}

std::string read_text(const std::string& path, std::uintmax_t most) {
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw Error(ErrorClass::Io, path + ": cannot open: " + ec.message());
  if (size > most) bad(path, "is " + std::to_string(size) + " bytes, more than such a text file holds");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in && !in.eof()) throw Error(ErrorClass::Io, path + ": cannot read");
  return text.str();
}

// The scan's images, turned by 180° about the detector centre: view v's row
// j is stored row (rows − 1 − j), reversed.
class RotatedProjections final : public ProjectionReader {
 public:
  explicit RotatedProjections(std::unique_ptr<ProjectionReader> stored)
      : ProjectionReader(stored->path(), stored->columns(), stored->rows(), stored->view_count()),
        stored_(std::move(stored)) {}
  StoredQuantity quantity() const override { return stored_->quantity(); }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    const std::size_t columns = static_cast<std::size_t>(columns_);
    band_.resize(static_cast<std::size_t>(row_end - row_begin) * columns);
    const std::uint64_t clamped = stored_->clamped_pixels();
    stored_->read_rows(view, rows_ - row_end, rows_ - row_begin, band_.data());
    count_clamped(stored_->clamped_pixels() - clamped);
    // band_ holds stored rows rows−row_end .. rows−row_begin−1; the last of
    // them is row row_begin here.
    const std::size_t count = band_.size();
    for (std::size_t i = 0; i < count; ++i) out[i] = band_[count - 1 - i];
  }

 private:
  std::unique_ptr<ProjectionReader> stored_;
  std::vector<float> band_;
};

}  // namespace

XtekctKeys parse_xtekct(const std::string& text, const std::string& path) {
  const Keys k(section_keys(text, path), path);
  XtekctKeys x;
  x.name = k.text("Name");
  x.input_folder = k.text("InputFolderName");
  x.projections = k.whole("Projections", 1e7);
  x.white_level = k.positive("WhiteLevel");
  x.pixels_x = static_cast<int>(k.whole("DetectorPixelsX", 65536));
  x.pixels_y = static_cast<int>(k.whole("DetectorPixelsY", 65536));
  x.pixel_size_x = k.positive("DetectorPixelSizeX");
  x.pixel_size_y = k.positive("DetectorPixelSizeY");
  x.src_to_object = k.positive("SrcToObject");
  x.src_to_detector = k.positive("SrcToDetector");
  if (!(x.src_to_detector > x.src_to_object))
    bad(path, "SrcToDetector " + number_text(x.src_to_detector) + " is not beyond SrcToObject " +
                  number_text(x.src_to_object) + " (mm)");
  x.initial_angle = k.number("InitialAngle", 0.0);
  x.angular_step = k.number("AngularStep");
  x.object_offset_x = k.optional("ObjectOffsetX");
  x.object_roll = k.optional("ObjectRoll");
  x.object_tilt = k.number("ObjectTilt", 0.0);
  x.centre_of_rotation_top = k.number("CentreOfRotationTop", 0.0);
  x.centre_of_rotation_bottom = k.number("CentreOfRotationBottom", 0.0);
  x.detector_offset_x = k.number("DetectorOffsetX", 0.0);
  x.detector_offset_y = k.number("DetectorOffsetY", 0.0);
  const char* voxels[] = {"VoxelsX", "VoxelsY", "VoxelsZ"};
  const char* sizes[] = {"VoxelSizeX", "VoxelSizeY", "VoxelSizeZ"};
  x.has_grid = true;
  for (int a = 0; a < 3; ++a) x.has_grid = x.has_grid && k.has(voxels[a]) && k.has(sizes[a]);
  if (x.has_grid)
    for (int a = 0; a < 3; ++a) {
      x.voxels[a] = static_cast<std::uint32_t>(k.whole(voxels[a], 1e6));
      x.voxel_size[a] = k.positive(sizes[a]);
    }
  return x;
}

std::vector<double> parse_ctdata_angles(const std::string& text, const std::string& path, std::uint64_t expected) {
  return indexed_angles(text, path, expected, false);
}

std::vector<double> parse_ang_angles(const std::string& text, const std::string& path, std::uint64_t expected) {
  return indexed_angles(text, path, expected, true);
}

XtekctGeometry xtekct_geometry(const XtekctKeys& k, const std::vector<double>& angles_deg, const std::string& path) {
  if (angles_deg.size() != k.projections)
    bad(path, std::to_string(angles_deg.size()) + " angles for Projections=" + std::to_string(k.projections));
  if (k.detector_offset_x != 0.0 || k.detector_offset_y != 0.0)
    bad(path, "DetectorOffsetX/Y = " + number_text(k.detector_offset_x) + ", " + number_text(k.detector_offset_y) +
                  ": a shifted detector is not mapped (its sign convention is not established); only 0, 0 is read");
  if (std::abs(k.object_tilt) > 1e-6)
    bad(path, "ObjectTilt = " + number_text(k.object_tilt) +
                  " degrees: ivol's geometry has a rotation axis perpendicular to the central ray");
  const double height = k.pixels_y * k.pixel_size_y;
  // A tilted axis (roll) that moves by more than a quarter of a pixel across
  // the detector's height cannot be represented.
  double roll_drift_mm = 0.0;
  std::string roll_from;
  if (k.object_roll) {
    roll_drift_mm = std::tan(*k.object_roll * M_PI / 180.0) * height;
    roll_from = "ObjectRoll = " + number_text(*k.object_roll) + " degrees";
  } else {
    roll_drift_mm = k.centre_of_rotation_top - k.centre_of_rotation_bottom;
    roll_from = "CentreOfRotationTop − CentreOfRotationBottom = " + number_text(roll_drift_mm) + " mm";
  }
  if (std::abs(roll_drift_mm) > 0.25 * k.pixel_size_x)
    bad(path, roll_from + ": the rotation axis leans by " + number_text(roll_drift_mm) + " mm over the detector's " +
                  number_text(height) + " mm; ivol's geometry has a vertical axis (at most a quarter pixel, " +
                  number_text(0.25 * k.pixel_size_x) + " mm)");
  XtekctGeometry g;
  double offset = 0.0;
  if (k.object_offset_x) {
    offset = *k.object_offset_x;
    g.mapping.emplace_back("source and detector offset u " + number_text(offset) + " mm", "ObjectOffsetX");
  } else {
    offset = 0.5 * (k.centre_of_rotation_top + k.centre_of_rotation_bottom) * k.src_to_object / k.src_to_detector;
    g.mapping.emplace_back("source and detector offset u " + number_text(offset) + " mm",
                           "(CentreOfRotationTop + CentreOfRotationBottom) / 2 · SrcToObject / SrcToDetector");
  }
  g.geometry.detector = {k.pixels_x, k.pixels_y, k.pixel_size_x, k.pixel_size_y};
  g.mapping.emplace_back("detector " + std::to_string(k.pixels_x) + "x" + std::to_string(k.pixels_y),
                         "DetectorPixelsX, DetectorPixelsY");
  g.mapping.emplace_back("pitch " + number_text(k.pixel_size_x) + ", " + number_text(k.pixel_size_y) + " mm",
                         "DetectorPixelSizeX, DetectorPixelSizeY");
  g.mapping.emplace_back("SID " + number_text(k.src_to_object) + " mm", "SrcToObject");
  g.mapping.emplace_back("SDD " + number_text(k.src_to_detector) + " mm", "SrcToDetector");
  for (double phi : angles_deg) {
    recon::View view;
    view.angle = (phi - 180.0) * M_PI / 180.0;
    view.source_to_isocenter = k.src_to_object;
    view.source_to_detector = k.src_to_detector;
    view.source_offset_u = offset;
    view.detector_offset_u = offset;
    g.geometry.views.push_back(view);
  }
  g.mapping.emplace_back("gantry angle θ = φ − 180°", "φ: the projection's stage angle");
  g.mapping.emplace_back("line integrals −log(I / " + number_text(k.white_level) + ")", "WhiteLevel");
  return g;
}

XtekctKeys read_xtekct(const std::string& path) {
  return parse_xtekct(read_text(path, std::uintmax_t{16} << 20), path);
}

XtekctFiles xtekct_files(const std::string& path, const XtekctKeys& k) {
  XtekctFiles files;
  const fs::path directory = fs::path(path).parent_path().empty() ? fs::path(".") : fs::path(path).parent_path();
  // InputFolderName is often the scanner PC's absolute path (C:\...); the
  // folder next to the .xtekct file is where a copied scan has it.
  fs::path folder = directory;
  std::error_code ec;
  if (!k.input_folder.empty()) {
    std::string relative = k.input_folder;
    std::replace(relative.begin(), relative.end(), '\\', '/');
    if (fs::is_directory(directory / relative, ec))
      folder = directory / relative;
    else if (fs::is_directory(directory / fs::path(relative).filename(), ec))
      folder = directory / fs::path(relative).filename();
  }
  if (!k.name.empty()) {
    files.source = (folder / (k.name + "_*.tif")).string();
    try {
      files.projections = resolve_tiff_files(files.source);
    } catch (const Error&) {
      files.projections.clear();
    }
  }
  if (files.projections.empty()) {
    files.source = folder.string();
    try {
      files.projections = resolve_tiff_files(files.source);
    } catch (const Error& e) {
      bad(path, "no projections: " + std::string(e.what()) + " (Name=" + k.name +
                    ", InputFolderName=" + k.input_folder + ")");
    }
  }
  const fs::path ctdata = directory / "_ctdata.txt";
  const fs::path ang = directory / (k.name + ".ang");
  if (fs::is_regular_file(ctdata, ec)) {
    files.angles = ctdata.string();
  } else if (!k.name.empty() && fs::is_regular_file(ang, ec)) {
    files.angles = ang.string();
    files.angles_are_ang = true;
  }
  return files;
}

XtekctScan open_xtekct(const std::string& path) {
  XtekctScan scan;
  scan.keys = read_xtekct(path);
  const XtekctKeys& k = scan.keys;
  const XtekctFiles files = xtekct_files(path, k);
  scan.projection_source = files.source;
  if (files.projections.size() != k.projections)
    bad(path, "Projections=" + std::to_string(k.projections) + " but " + files.source + " holds " +
                  std::to_string(files.projections.size()) + " TIFF files");
  IntensityOptions intensity;
  intensity.incident_intensity = k.white_level;
  auto stored = open_tiff_projections(files.projections, StoredQuantity::Intensities, intensity);
  if (stored->columns() != k.pixels_x || stored->rows() != k.pixels_y)
    bad(path, "DetectorPixelsX/Y = " + std::to_string(k.pixels_x) + "x" + std::to_string(k.pixels_y) +
                  " but the projections are " + std::to_string(stored->columns()) + "x" +
                  std::to_string(stored->rows()) + " pixels");
  scan.projections = std::make_unique<RotatedProjections>(std::move(stored));

  // Angles φ: measured ones when the scan has them, InitialAngle added as
  // public readers do; else the nominal steps.
  std::vector<double> angles;
  if (!files.angles.empty()) {
    const std::string text = read_text(files.angles, 64 << 20);
    angles = files.angles_are_ang ? parse_ang_angles(text, files.angles, k.projections)
                                  : parse_ctdata_angles(text, files.angles, k.projections);
    scan.angles_from = files.angles + " + InitialAngle";
  } else {
    angles.resize(k.projections);
    for (std::uint64_t i = 0; i < k.projections; ++i) angles[i] = static_cast<double>(i) * k.angular_step;
    scan.angles_from = "InitialAngle + i · AngularStep";
  }
  for (double& a : angles) a += k.initial_angle;
  scan.geometry = xtekct_geometry(k, angles, path);
  return scan;
}

}  // namespace ivol::convert
