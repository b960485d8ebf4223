// The options of `ivol recon` that say where a scan's projections are and how
// it was taken, and the opening of both.
#pragma once

#include <CLI/CLI.hpp>
#include <array>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/projections.hpp"

namespace ivol::cli {

struct ScanSettings {
  std::string projections;  // file, folder or glob
  std::string format;       // raw, tiff, hdf5, itk, xtekct; default by extension
  // raw
  std::string detector;  // C,R
  std::size_t views = 0;
  std::string sample = "f32";
  std::uint64_t header_bytes = 0;
  // hdf5
  std::string dataset;  // empty: /exchange/data or the NXtomo entry
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
  // What the child process reading HDF5 projections may allocate (recon's
  // --memory); 0: its default.
  std::uint64_t memory_bytes = 0;
};

void add_scan_options(CLI::App* command, ScanSettings& settings);

struct OpenedScan {
  std::unique_ptr<recon::ProjectionSource> projections;
  recon::ScanGeometry geometry;
  nlohmann::json description;      // for the file's provenance
  std::vector<std::string> notes;  // what was done to the projections, for the user
  // Doubtful but usable geometry, each naming its numbers (recon prints them).
  std::vector<std::string> warnings;
  // The grid the scan's own files propose (a Nikon scan's VoxelsX/Y/Z and
  // VoxelSizeX/Y/Z), for a recon without --size and --voxel.
  bool has_grid = false;
  std::array<std::uint32_t, 3> grid_size{0, 0, 0};
  std::array<double, 3> grid_voxel{0.0, 0.0, 0.0};
  std::string grid_from;
};

// The files a scan reads besides PROJECTIONS and the options' files (a Nikon
// scan's TIFF folder and angle file), with their roles, for provenance.
std::vector<std::pair<std::string, std::string>> scan_companion_files(const ScanSettings& settings);

// Throws ivol::Error (InvalidArgument) naming the option for bad options,
// std::runtime_error naming the file for unreadable inputs.
OpenedScan open_scan(const ScanSettings& settings);

}  // namespace ivol::cli
