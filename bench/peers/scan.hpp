// Simulated scans for peers_bench: an industrial phantom of recon/phantom.hpp
// scanned on a circular cone-beam trajectory with Poisson noise, and the
// dense FDK reconstruction of it (cached on disk so that reruns are quick).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"

namespace peers {

struct ScanSetup {
  std::uint32_t size = 256;  // volume edge in voxels of 1 mm
  std::size_t views = 360;
  int detector = 384;    // pixels per detector edge; default 1.5 · size
  double photons = 1e5;  // incident photons per pixel (Poisson noise)
  std::uint64_t seed = 1;
};

// SID/SDD 600/1200 mm, full circle, a detector that sees the whole volume at
// magnification 2 with 20 % spare (as bench/recon_bench.cpp).
ivol::recon::ScanGeometry scan_geometry(const ScanSetup& setup);
ivol::recon::VolumeGrid volume_grid(const ScanSetup& setup);
double detector_pitch(const ScanSetup& setup);

// Exact line integrals of the phantom with photon noise.
ivol::recon::InMemoryProjections noisy_scan(const std::string& phantom, const ScanSetup& setup);

// The dense float32 FDK reconstruction of the noisy scan, [z][y][x]; read
// from `cache_dir` when it is there, else computed and stored there.
std::vector<float> reconstructed_volume(const std::string& phantom, const ScanSetup& setup,
                                        const std::string& cache_dir);

// Reconstruction against RTK: the noisy scan reconstructed dense and through
// the paper's octree pipeline (timed), one JSON line on stdout; exports the
// projections, RTK's geometry XML, both volumes and the voxelised phantom to
// `export_dir` for bench/rtk/rtk_fdk.py and the accuracy comparison.
void reconstruction_run(const std::string& phantom, const ScanSetup& setup, const std::string& export_dir);

}  // namespace peers
