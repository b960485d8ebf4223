#include "scan_input.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "ivol/error.hpp"
#include "ivol/recon/displaced_detector.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"
#include "option_parsing.hpp"
#include "projection_io.hpp"
#include "xtekct.hpp"

namespace ivol::cli {
namespace {

// Every complaint here is about the command line (exit 1).
[[noreturn]] void bad(const std::string& message) { throw UsageError("", message); }

// Header values are written with a few digits; the same value typed on the
// command line agrees to a part in 10^6.
bool close_to(double a, double b) { return std::abs(a - b) <= 1e-6 * std::max({1.0, std::abs(a), std::abs(b)}); }

std::string number_text(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", v);
  return text;
}

std::string lower_extension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

std::string detect_format(const ScanSettings& s) {
  if (!s.format.empty()) return s.format;
  if (std::filesystem::is_directory(s.projections)) return "tiff";
  const std::string e = lower_extension(s.projections);
  if (e == ".h5" || e == ".hdf5" || e == ".hdf" || e == ".nxs" || e == ".nx") return "hdf5";
  if (e == ".xtekct") return "xtekct";
  if (e == ".tif" || e == ".tiff") return "tiff";
  if (e == ".raw" || e == ".bin") return "raw";
  if (e == ".mha" || e == ".mhd" || e == ".nrrd" || e == ".nhdr") return "itk";
  bad(s.projections + ": cannot tell the format from the name; give --format raw|tiff|hdf5|itk|xtekct");
}

}  // namespace

void add_scan_options(CLI::App* cmd, ScanSettings& s) {
  cmd->add_option("PROJECTIONS", s.projections,
                  "Projections: raw file, TIFF file/folder/glob, HDF5 (NeXus NXtomo or DXchange), an ITK image stack "
                  "(MetaImage .mha/.mhd, NRRD .nrrd/.nhdr, as RTK writes them), or a Nikon XT scan's .xtekct file")
      ->required();
  cmd->add_option("--format", s.format, "raw, tiff, hdf5, itk or xtekct (default: by extension)")
      ->check(CLI::IsMember({"raw", "tiff", "hdf5", "itk", "xtekct"}));
  auto* raw = cmd->add_option_group("raw projections");
  raw->add_option("--detector", s.detector, "C,R: detector columns and rows")->check(checked([](const std::string& v) {
    for (double c : parse_numbers(v, "--detector", 2, 2))
      if (c < 1 || c > 65536 || c != std::floor(c)) throw UsageError("--detector", "'" + v + "' is not C,R pixels");
  }));
  raw->add_option("--views", s.views, "Number of projections")->check(whole_number());
  raw->add_option("--sample", s.sample, "f32 or u16")->check(CLI::IsMember({"f32", "u16"}))->capture_default_str();
  raw->add_option("--header-bytes", s.header_bytes, "Bytes to skip at the start of each raw file")
      ->check(whole_number());
  cmd->add_option("--dataset", s.dataset,
                  "HDF5 projections: the (views, rows, columns) dataset, read as DXchange's /exchange/data "
                  "(default: /exchange/data, or the file's NXtomo entry)");
  auto* intensity = cmd->add_option_group("intensities");
  intensity->add_flag("--intensities", s.intensities, "Values are intensities, not line integrals (u16 always are)");
  intensity->add_option("--flat", s.flats, "Flat (bright) field file(s), averaged");
  intensity->add_option("--dark", s.darks, "Dark field file(s), averaged");
  intensity->add_option("--incident", s.incident, "Unattenuated intensity, when there is no flat field")
      ->check(number_in(0, 1e30));
  auto* geometry = cmd->add_option_group("geometry");
  geometry->add_option("--geometry", s.geometry_xml, "RTK geometry XML (ThreeDCircularProjectionGeometry)");
  geometry
      ->add_option("--pitch", s.pitch,
                   "U or U,V: detector pixel pitch in mm (default: an ITK image's spacing; required otherwise)")
      ->check(checked([](const std::string& v) {
        for (double p : parse_numbers(v, "--pitch", 1, 2))
          if (!(p > 0)) throw UsageError("--pitch", "'" + v + "' is not positive");
      }));
  geometry
      ->add_option("--projection-origin", s.projection_origin,
                   "U,V: RTK projection image origin in mm (default: an ITK image's origin, else centred)")
      ->check(checked([](const std::string& v) { parse_numbers(v, "--projection-origin", 2, 2); }));
  geometry->add_option("--sid", s.sid, "Source to isocentre distance, mm (without --geometry)")
      ->check(number_in(0, 1e9, true));
  geometry->add_option("--sdd", s.sdd, "Source to detector distance, mm (without --geometry)")
      ->check(number_in(0, 1e9, true));
  geometry->add_option("--arc", s.arc_deg, "Degrees covered by the views (without --geometry)")
      ->check(number_in(0, 360, true))
      ->capture_default_str();
  geometry->add_option("--first-angle", s.first_angle_deg, "Angle of the first view, degrees")
      ->check(number_in(-1e6, 1e6))
      ->capture_default_str();
  geometry->add_option("--offset", s.offset, "U,V: detector offset in mm (without --geometry)")
      ->check(checked([](const std::string& v) { parse_numbers(v, "--offset", 2, 2); }));
}

// A detector shifted sideways sees part of the object from one side only:
// its projections are weighted (Wang) and widened before FDK sees them, as
// RTK's rtkfdk does. A detector that never sees the axis is refused.
void weight_displaced_detector(const std::string& projections, OpenedScan& scan) {
  recon::DisplacedDetector displaced;
  try {
    displaced = recon::analyse_displaced_detector(scan.geometry);
  } catch (const std::invalid_argument& e) {
    bad(projections + ": " + e.what());
  }
  scan.description["geometry"]["displaced_detector"] = {{"weighting", displaced.weighted() ? "wang" : "none"},
                                                        {"columns_span_mm", {displaced.inferior, displaced.superior}},
                                                        {"overlap_mm", displaced.overlap},
                                                        {"padding_columns", displaced.padding}};
  if (!displaced.weighted()) return;
  scan.notes.push_back(displaced.describe());
  const recon::ScanGeometry measured = scan.geometry;
  scan.geometry = recon::widen_for_displaced_detector(measured, displaced);
  scan.projections =
      std::make_unique<recon::DisplacedDetectorProjections>(std::move(scan.projections), measured, displaced);
}

namespace {

// A Nikon scan's .xtekct file gives its whole geometry; an option that
// would also give some of it is a contradiction waiting to happen.
void refuse_options_beside(const ScanSettings& s, const std::string& what) {
  const std::pair<bool, const char*> given[] = {{!s.geometry_xml.empty(), "--geometry"},
                                                {!s.pitch.empty(), "--pitch"},
                                                {!s.projection_origin.empty(), "--projection-origin"},
                                                {s.sid > 0, "--sid"},
                                                {s.sdd > 0, "--sdd"},
                                                {!s.offset.empty(), "--offset"},
                                                {s.arc_deg != 360.0, "--arc"},
                                                {s.first_angle_deg != 0.0, "--first-angle"},
                                                {!s.detector.empty(), "--detector"},
                                                {s.views != 0, "--views"},
                                                {s.header_bytes != 0, "--header-bytes"},
                                                {!s.dataset.empty(), "--dataset"},
                                                {!s.flats.empty(), "--flat"},
                                                {!s.darks.empty(), "--dark"},
                                                {s.incident > 0, "--incident"},
                                                {s.intensities, "--intensities"}};
  for (const auto& [is_given, option] : given)
    if (is_given) throw UsageError(option, s.projections + " " + what + "; leave " + option + " out");
}

OpenedScan open_nikon_scan(const ScanSettings& s) {
  refuse_options_beside(s, "gives the scan's geometry, detector and white level (a Nikon XT .xtekct file)");
  convert::XtekctScan x = convert::open_xtekct(s.projections);
  OpenedScan scan;
  scan.projections = std::move(x.projections);
  scan.geometry = std::move(x.geometry.geometry);
  nlohmann::json mapping = nlohmann::json::array();
  for (const auto& [value, from] : x.geometry.mapping) mapping.push_back({{"value", value}, {"from", from}});
  scan.description["geometry"] = {{"xtekct", s.projections}, {"angles_from", x.angles_from}, {"mapping", mapping}};
  const recon::Detector& d = scan.geometry.detector;
  scan.description["projections"] = {{"path", x.projection_source},
                                     {"format", "xtekct"},
                                     {"views", scan.projections->view_count()},
                                     {"detector", {d.columns, d.rows}},
                                     {"pitch_mm", {d.pitch_u, d.pitch_v}},
                                     {"pitch_from", s.projections + " DetectorPixelSizeX, DetectorPixelSizeY"},
                                     {"quantity", "intensities"},
                                     {"white_level", x.keys.white_level}};
  if (x.keys.has_grid) {
    scan.has_grid = true;
    scan.grid_size = x.keys.voxels;
    scan.grid_voxel = x.keys.voxel_size;
    scan.grid_from = s.projections + " VoxelsX/Y/Z, VoxelSizeX/Y/Z";
  }
  return scan;
}

// A length both the file and an option give: they must agree.
double agreed(double option, const convert::LengthField& file, const char* name, const std::string& path,
              std::string& from) {
  if (option > 0) {
    if (file.present && !close_to(option, file.mm))
      bad(std::string(name) + " " + number_text(option) + " disagrees with " + path + "'s " + file.field + " (" +
          number_text(file.mm) + " mm); leave " + name + " out to use the file's");
    from = name;
    return option;
  }
  if (!file.present) return 0.0;
  from = path + " " + file.field;
  return file.mm;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> scan_companion_files(const ScanSettings& s) {
  std::vector<std::pair<std::string, std::string>> files;
  if (detect_format(s) != "xtekct") return files;
  const convert::XtekctKeys keys = convert::read_xtekct(s.projections);
  const convert::XtekctFiles x = convert::xtekct_files(s.projections, keys);
  for (const std::string& f : x.projections) files.emplace_back(f, "projections");
  if (!x.angles.empty()) files.emplace_back(x.angles, "angles");
  return files;
}

OpenedScan open_scan(const ScanSettings& s) {
  const std::string format = detect_format(s);
  if (!s.dataset.empty() && format != "hdf5")
    throw UsageError("--dataset", s.projections + " is " + format + ", not HDF5: it has no datasets to name");
  if (format == "xtekct") {
    OpenedScan scan = open_nikon_scan(s);
    weight_displaced_detector(s.projections, scan);
    return scan;
  }
  OpenedScan scan;
  convert::IntensityOptions intensity;
  intensity.flat_paths = s.flats;
  intensity.dark_paths = s.darks;
  intensity.incident_intensity = s.incident;
  const bool intensities = s.intensities || !s.flats.empty() || s.incident > 0;
  const auto quantity = intensities ? convert::StoredQuantity::Intensities : convert::StoredQuantity::LineIntegrals;
  std::vector<double> theta_deg;
  std::string theta_from;
  // What an ITK image's header or an NXtomo file says of the detector:
  // values and the field.
  struct HeaderPair {
    double u = 0, v = 0;
    std::string field;
  };
  std::optional<HeaderPair> header_pitch, header_origin;
  convert::LengthField file_sid, file_sdd;  // NXtomo's distances
  std::string hdf5_layout;
  const std::string lower = lower_extension(s.projections);
  if (format == "raw" && (lower == ".mha" || lower == ".mhd" || lower == ".nrrd" || lower == ".nhdr"))
    scan.warnings.push_back(s.projections +
                            " is an ITK image read as raw samples: its header's spacing and origin are not used "
                            "(leave --format raw out to read them)");
  if (format == "raw") {
    if (s.detector.empty() || s.views == 0) bad("raw projections need --detector C,R and --views V");
    const std::vector<double> d = parse_numbers(s.detector, "--detector", 2, 2);
    convert::RawProjectionLayout layout;
    layout.columns = static_cast<int>(d[0]);
    layout.rows = static_cast<int>(d[1]);
    layout.views = s.views;
    layout.sample = s.sample == "u16" ? convert::RawSampleType::UInt16 : convert::RawSampleType::Float32;
    layout.quantity = quantity;
    layout.header_bytes = s.header_bytes;
    scan.projections = convert::open_raw_projections(s.projections, layout, intensity);
  } else if (format == "tiff") {
    scan.projections = convert::open_tiff_projections(s.projections, quantity, intensity);
  } else if (format == "itk") {
    convert::ItkImageScan image = convert::open_itk_image_projections(s.projections, quantity, intensity);
    scan.projections = std::move(image.projections);
    if (!image.unit.empty() && image.unit != "mm" && (image.has_pitch || image.has_origin))
      bad(s.projections + ": the image's space units are '" + image.unit +
          "'; ivol's geometry is in mm: give --pitch and --projection-origin in mm");
    if (image.has_pitch) header_pitch = {image.pitch[0], image.pitch[1], image.pitch_field};
    if (image.has_origin) header_origin = {image.origin[0], image.origin[1], image.origin_field};
  } else {
    convert::DxchangeOptions options;
    options.assume_line_integrals = !intensities;
    options.dataset = s.dataset;
    options.memory_bytes = s.memory_bytes;
    convert::Hdf5Scan h = convert::open_hdf5_projections(s.projections, options);
    scan.projections = std::move(h.projections);
    theta_deg = std::move(h.angles_deg);
    theta_from = h.angles_field;
    hdf5_layout = h.layout;
    if (h.pitch_u.present) {
      const convert::LengthField& v = h.pitch_v.present ? h.pitch_v : h.pitch_u;
      header_pitch = {h.pitch_u.mm, v.mm, h.pitch_u.field + ", " + v.field};
    }
    file_sid = h.source_sample;
    if (h.source_sample.present && h.sample_detector.present)
      file_sdd = {true, h.source_sample.mm + h.sample_detector.mm,
                  h.source_sample.field + " + " + h.sample_detector.field};
    if (h.layout == "NXtomo")
      scan.description["nxtomo"] = {{"entry", h.entry},
                                    {"flat_images", h.flat_images},
                                    {"dark_images", h.dark_images},
                                    {"invalid_images_skipped", h.skipped_images}};
  }
  recon::ProjectionSource& p = *scan.projections;

  // The pitch: --pitch, else the file's. Both given and different is a
  // mistake in one of them.
  std::string pitch_from = "--pitch";
  std::vector<double> pitch;
  if (!s.pitch.empty()) {
    pitch = parse_numbers(s.pitch, "--pitch", 1, 2);
    if (pitch.size() == 1) pitch.push_back(pitch[0]);
    if (header_pitch && (!close_to(pitch[0], header_pitch->u) || !close_to(pitch[1], header_pitch->v)))
      bad("--pitch " + s.pitch + " disagrees with " + s.projections + "'s " + header_pitch->field + " (" +
          number_text(header_pitch->u) + ", " + number_text(header_pitch->v) +
          " mm); leave --pitch out to use the file's");
  } else if (header_pitch) {
    pitch = {header_pitch->u, header_pitch->v};
    pitch_from = s.projections + " " + header_pitch->field;
  } else {
    bad("--pitch is required: the detector pixel pitch in mm (" + s.projections + " does not give it)");
  }
  recon::Detector detector{p.columns(), p.rows(), pitch[0], pitch[1]};
  if (!(detector.pitch_u > 0) || !(detector.pitch_v > 0)) bad("--pitch: must be positive");
  // The projection origin: --projection-origin, else the image's origin,
  // else the centred one.
  const double centred_u = -0.5 * (detector.columns - 1) * detector.pitch_u;
  const double centred_v = -0.5 * (detector.rows - 1) * detector.pitch_v;
  double origin_u = centred_u, origin_v = centred_v;
  std::string origin_from = "centred";
  if (!s.projection_origin.empty()) {
    const std::vector<double> o = parse_numbers(s.projection_origin, "--projection-origin", 2, 2);
    origin_u = o[0];
    origin_v = o[1];
    origin_from = "--projection-origin";
    if (header_origin && (!close_to(o[0], header_origin->u) || !close_to(o[1], header_origin->v)))
      bad("--projection-origin " + s.projection_origin + " disagrees with " + s.projections + "'s " +
          header_origin->field + " (" + number_text(header_origin->u) + ", " + number_text(header_origin->v) +
          " mm); leave it out to use the image's");
  } else if (header_origin) {
    origin_u = header_origin->u;
    origin_v = header_origin->v;
    origin_from = s.projections + " " + header_origin->field;
  }
  if (!s.geometry_xml.empty()) {
    if (s.sid > 0 || s.sdd > 0 || !s.offset.empty())
      bad("--geometry gives the distances and offsets of every view; leave --sid, --sdd and --offset out");
    scan.geometry = recon::read_rtk_geometry_xml(s.geometry_xml, detector, origin_u, origin_v);
    scan.description["geometry"] = {{"rtk_xml", s.geometry_xml},
                                    {"projection_origin_mm", {origin_u, origin_v}},
                                    {"projection_origin_from", origin_from}};
  } else {
    std::string sid_from, sdd_from;
    const double sid = agreed(s.sid, file_sid, "--sid", s.projections, sid_from);
    const double sdd = agreed(s.sdd, file_sdd, "--sdd", s.projections, sdd_from);
    if (hdf5_layout == "NXtomo" && !(sid > 0))
      bad(s.projections +
          ": the NXtomo entry has no instrument/source/distance: as far as the file says it is a "
          "parallel-beam scan, and ivol reconstructs cone-beam scans only (FDK); if it is a cone-beam scan, give "
          "--sid and --sdd in mm");
    if (hdf5_layout == "NXtomo" && !(sdd > 0))
      bad(s.projections +
          ": the NXtomo entry has no instrument/detector/distance (sample to detector); give --sdd "
          "(source to detector, mm)");
    if (!(sid > 0) || !(sdd > sid))
      bad("without --geometry, give --sid and --sdd (mm, SDD > SID) and optionally --arc, --first-angle, --offset");
    std::vector<double> offset{0.0, 0.0};
    if (!s.offset.empty()) offset = parse_numbers(s.offset, "--offset", 2, 2);
    // An origin away from the centred one shifts the detector, as RTK's
    // projection origin does (rtk_geometry_xml.cpp's to_view). Given with
    // --offset too, both shifts add: say so.
    const double shift_u = origin_u - centred_u, shift_v = origin_v - centred_v;
    if (!s.offset.empty() && header_origin && s.projection_origin.empty() &&
        (std::abs(shift_u) > 1e-9 || std::abs(shift_v) > 1e-9))
      scan.warnings.push_back("--offset " + s.offset + " and " + origin_from + " (which shifts the detector by " +
                              number_text(shift_u) + ", " + number_text(shift_v) + " mm) both apply: the detector is " +
                              "offset by " + number_text(offset[0] + shift_u) + ", " +
                              number_text(offset[1] + shift_v) + " mm in all");
    offset[0] += shift_u;
    offset[1] += shift_v;
    scan.geometry = recon::circular_scan(detector, p.view_count(), sid, sdd, s.arc_deg * M_PI / 180.0,
                                         s.first_angle_deg * M_PI / 180.0, offset[0], offset[1]);
    if (!theta_deg.empty()) {
      if (theta_deg.size() != p.view_count())
        throw std::runtime_error(s.projections + ": " + theta_from + " has " + std::to_string(theta_deg.size()) +
                                 " angles for " + std::to_string(p.view_count()) + " projections");
      for (std::size_t v = 0; v < theta_deg.size(); ++v) scan.geometry.views[v].angle = theta_deg[v] * M_PI / 180.0;
    }
    scan.description["geometry"] = {{"sid_mm", sid},
                                    {"sdd_mm", sdd},
                                    {"sid_from", sid_from},
                                    {"sdd_from", sdd_from},
                                    {"detector_offset_mm", offset},
                                    {"projection_origin_from", origin_from},
                                    {"angles", theta_deg.empty() ? std::string("uniform") : theta_from}};
    if (theta_deg.empty()) {
      scan.description["geometry"]["arc_deg"] = s.arc_deg;
      scan.description["geometry"]["first_angle_deg"] = s.first_angle_deg;
    }
  }
  scan.geometry.validate();
  if (scan.geometry.view_count() != p.view_count())
    throw std::runtime_error(s.geometry_xml + ": " + std::to_string(scan.geometry.view_count()) +
                             " projections in the geometry, " + std::to_string(p.view_count()) + " in " +
                             s.projections);
  const auto* reader = dynamic_cast<const convert::ProjectionReader*>(&p);
  const bool stored_intensities = reader ? reader->quantity() == convert::StoredQuantity::Intensities : intensities;
  scan.description["projections"] = {{"path", s.projections},
                                     {"format", format},
                                     {"views", p.view_count()},
                                     {"detector", {detector.columns, detector.rows}},
                                     {"pitch_mm", {detector.pitch_u, detector.pitch_v}},
                                     {"pitch_from", pitch_from},
                                     {"quantity", stored_intensities ? "intensities" : "line_integrals"}};
  if (!hdf5_layout.empty()) scan.description["projections"]["layout"] = hdf5_layout;
  weight_displaced_detector(s.projections, scan);
  if (!scan.warnings.empty()) scan.description["warnings"] = scan.warnings;
  return scan;
}

}  // namespace ivol::cli
