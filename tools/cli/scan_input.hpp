// The options of `ivol recon` that say where a scan's projections are and how
// it was taken, and the opening of both.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/projections.hpp"

namespace ivol::cli {

struct ScanSettings {
  std::string projections;  // file, folder or glob
  std::string format;       // raw, tiff, hdf5; default by extension
  // raw
  std::string detector;  // C,R
  std::size_t views = 0;
  std::string sample = "f32";
  std::uint64_t header_bytes = 0;
  // intensities
  bool intensities = false;
  std::vector<std::string> flats, darks;
  double incident = 0.0;
  // geometry
  std::string geometry_xml;
  std::string pitch;              // U or U,V
  std::string projection_origin;  // U,V of an RTK projection image
  double sid = 0.0, sdd = 0.0;
  double arc_deg = 360.0, first_angle_deg = 0.0;
  std::string offset;  // U,V detector offset in mm
};

void add_scan_options(CLI::App* command, ScanSettings& settings);

struct OpenedScan {
  std::unique_ptr<recon::ProjectionSource> projections;
  recon::ScanGeometry geometry;
  nlohmann::json description;      // for the file's provenance
  std::vector<std::string> notes;  // what was done to the projections, for the user
};

// Throws ivol::Error (InvalidArgument) naming the option for bad options,
// std::runtime_error naming the file for unreadable inputs.
OpenedScan open_scan(const ScanSettings& settings);

}  // namespace ivol::cli
