// Feldkamp–Davis–Kress cone-beam reconstruction on OpenCL devices.
//
// The volume is reconstructed in slabs of whole z-slices, each small enough
// for the device's memory; a slab reads only the detector rows its voxels
// project onto, filters them on the device and backprojects them. Finished
// slabs are handed to the caller in z order, so a caller that writes them out
// (an .ivol streaming writer) never holds the dense volume. A voxel's value
// does not depend on how the volume was cut into slabs.
#pragma once

#include <climits>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "ivol/recon/geometry.hpp"
#include "ivol/recon/projections.hpp"
#include "ivol/recon/slab_exchange.hpp"
#include "ivol/structure_stream.hpp"
#include "ivol/structures.hpp"

namespace ivol::recon {

// Apodisation of the ramp filter, as a function of frequency over Nyquist.
enum class RampWindow { RamLak, SheppLogan, Cosine, Hamming, Hann };
const char* ramp_window_name(RampWindow window);
// "ram-lak", "shepp-logan", "cosine", "hamming", "hann"; throws
// std::invalid_argument listing the names otherwise.
RampWindow parse_ramp_window(const std::string& name);

struct FdkOptions {
  RampWindow window = RampWindow::RamLak;
  // Frequencies above cutoff × Nyquist are removed; 1 keeps them all.
  double cutoff = 1.0;
  // Which OpenCL devices to use: empty means every GPU, or the first CPU
  // device when there is no GPU. Entries are indices into list_devices().
  std::vector<int> devices;
  // Bytes of device memory one device may use; 0 takes 80 % of what the
  // device reports. Slabs are cut to fit.
  std::uint64_t device_memory_limit = 0;
  // On CPU devices, whose memory is the host's: bytes all CPU devices
  // together may use when device_memory_limit is 0, instead of 80 % of what
  // each reports (PoCL reports most of the RAM). 0 keeps the 80 %.
  std::uint64_t cpu_device_memory_limit = 0;
  // Upper bound on a slab's slices; 0 means no bound beyond memory.
  std::uint32_t max_slab_slices = 0;
  // Keep the FFT scratch in global memory even where local memory would do
  // (for testing the path long detectors take on GPUs).
  bool fft_in_global_memory = false;
  // On a CPU device whose processor has AVX-512, backproject dense slabs in
  // native code instead of the OpenCL kernel: the same bits, several times
  // faster than PoCL's vectorisation of the kernel (bench/RESULTS.md,
  // fdk_bench). false keeps the kernel (to compare the two). Filtering and
  // the structure path stay on OpenCL.
  bool native_cpu_backprojection = true;
  // Filter each detector row of each view once, however many slabs read
  // it: filtered rows are kept, in host memory up to
  // filtered_rows_memory_limit and the rest in a temporary file, until no
  // later slab reads them. Calls of reconstruct() in increasing z (the
  // CLI's writer slabs) share them too. false filters each slab's rows for that slab (to
  // compare the two; the same bits either way).
  bool cache_filtered_rows = true;
  // Bytes of host memory the filtered rows may take; 0 means a quarter of
  // the physical memory. Rows beyond it go to an unlinked temporary file.
  std::uint64_t filtered_rows_memory_limit = 0;
  // Where that file goes; empty means $TMPDIR, else /tmp.
  std::string temp_directory;
  // With an exchange, this process is one rank of a distributed
  // reconstruction (slab_exchange.hpp): it reconstructs only the slabs it
  // owns, and only rank 0's sink (or structure) receives the volume. Slabs
  // are cut thin enough that every rank gets at least one.
  std::shared_ptr<SlabExchange> exchange;
};

// Where the time went, in seconds of wall clock (phases overlap between
// devices, so they need not sum to the total).
struct FdkTimings {
  double setup = 0;           // devices, kernels, plans
  double reading = 0;         // ProjectionSource::read_rows
  double filtering = 0;       // weighting and ramp filter on the device
  double backprojection = 0;  // backprojection kernels
  double transfer = 0;        // host <-> device copies
  double delivery = 0;        // the caller's slab callback
  double total = 0;
};

struct FdkReport {
  FdkTimings timings;
  std::size_t slab_count = 0;
  std::uint32_t slab_slices = 0;            // slices of a full slab
  std::uint64_t device_bytes_per_slab = 0;  // device memory one slab used
  bool short_scan = false;
  std::vector<std::string> devices;  // names of the devices used
  // Per device: "opencl" (the kernel) or "native-avx512" (dense slabs
  // backprojected in native code on a CPU device).
  std::vector<std::string> backprojectors;
  std::vector<std::string> warnings;  // e.g. an arc too short for Parker
  // Voxel updates per second of backprojection (voxels × views / time; a
  // coarse voxel's eight samples count as eight).
  double gups() const;
  std::uint64_t voxel_updates = 0;
  // Detector rows through the ramp filter in this call, summed over views:
  // with cache_filtered_rows at most views × detector rows per reconstructor
  // (rows filtered by an earlier call are not filtered again).
  std::uint64_t rows_filtered = 0;
  // The most the filtered rows took at once so far (this reconstructor), in
  // host memory and in the temporary file: about the rows of the slabs in
  // flight, since rows no later slab reads are released (0 without
  // cache_filtered_rows).
  std::uint64_t filtered_rows_host_bytes = 0;
  std::uint64_t filtered_rows_disk_bytes = 0;
  // The structure path with a value window bound: the most the model of the
  // value window gave for the slabs chosen (0 without a bound).
  std::uint64_t value_window_model_bytes = 0;
  // The structure path: the index of the bricks by slab (lists, stacking,
  // and at its peak the thin bricks sorted for stacking), and the most the
  // task lists of the slabs in flight held at once.
  std::uint64_t slab_index_bytes = 0;
  std::uint64_t slab_tasks_peak_bytes = 0;
  std::uint64_t slab_tasks_model_bytes = 0;  // what the bound counted for them (see ValueWindowBound)
};

// Receives slices [k_begin, k_end) of the volume, nx·ny·(k_end − k_begin)
// floats with x fastest, in increasing k, from one thread.
using SlabSink = std::function<void(std::uint32_t k_begin, std::uint32_t k_end, const float* data)>;

// Keeps the devices, their compiled kernels and the scan's filter setup
// between reconstructions of the same scan: several grids (a quick
// low-resolution pass, then the full one) or parts of one grid.
class FdkReconstructor {
 public:
  FdkReconstructor(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options = {});
  ~FdkReconstructor();
  FdkReconstructor(const FdkReconstructor&) = delete;
  FdkReconstructor& operator=(const FdkReconstructor&) = delete;

  // Slices [k_begin, k_end) of `grid`, each voxel with the same bits as in a
  // reconstruction of the whole grid.
  FdkReport reconstruct(const VolumeGrid& grid, const SlabSink& sink, std::uint32_t k_begin = 0,
                        std::uint32_t k_end = UINT32_MAX);
  // Backprojects into the voxels of `structure` (its full-resolution voxel
  // (x, y, z) is voxel (i, j, k) of `grid`) and sets structure.values().
  // Full-resolution voxels get the bits a dense reconstruction gives them;
  // a coarse voxel is the mean over the centres of its eight octants, so it
  // averages the object instead of aliasing it. Work is in proportion to the
  // structure's voxels, not the grid's.
  FdkReport reconstruct_structure(const VolumeGrid& grid, VoxelStructure& structure);
  // The same, streaming: each voxel's value goes into `values` when the slab
  // computing it is done, and then progress(z_complete) says that every voxel
  // starting below slice z_complete is final (z_complete never decreases;
  // the last call gives the grid's depth). A StructureStreamWriter can write
  // those voxels and let `values` forget them, so neither the dense volume
  // nor the structure's values are ever held whole. Host memory: the values
  // of the voxels between the writer's slab and the slabs in flight, the
  // task lists of the slabs in flight (32 bytes per 128 full-resolution
  // voxels, 36 per lone voxel), and 4 to 8 bytes per brick.
  //
  // window: with a memory_limit, slabs are cut thinner (halved) until the
  // values in flight by a model of `values` (its pages and tall voxels
  // between the writer, `writer_slab_slices` behind in whole writer slabs,
  // and the slab being delivered) and the task lists of the slabs in flight
  // (the largest 2 × devices + 1 slabs' lists) fit it together;
  // FdkReport::value_window_model_bytes and slab_tasks_model_bytes say what
  // the models gave. When one-slice slabs do not fit either,
  // throws Error(LimitExceeded) naming the bytes needed and the limit.
  using StructureProgress = std::function<void(std::uint32_t z_complete)>;
  struct ValueWindowBound {
    std::uint64_t memory_limit = 0;  // 0: none
    std::uint32_t writer_slab_slices = 0;
  };
  FdkReport reconstruct_structure(const VolumeGrid& grid, const VoxelStructure& structure, StructureValueWindow& values,
                                  const StructureProgress& progress, const ValueWindowBound& window);
  FdkReport reconstruct_structure(const VolumeGrid& grid, const VoxelStructure& structure, StructureValueWindow& values,
                                  const StructureProgress& progress) {
    return reconstruct_structure(grid, structure, values, progress, ValueWindowBound{});
  }

  // Changes FdkOptions::cpu_device_memory_limit for the reconstructions to
  // come (the CLI's budget, once the structure's own memory is known).
  void set_cpu_device_memory_limit(std::uint64_t bytes);

  std::vector<std::string> device_names() const;
  // Warnings about the scan (e.g. a short arc), known before reconstructing.
  const std::vector<std::string>& warnings() const;
  // Whether the views cover less than a full circle (Parker weights apply).
  bool short_scan() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The most bytes the filtered rows of a scan of `geometry` can take in the
// temporary file with `host_budget` bytes of host memory (0: the default,
// as FdkOptions::filtered_rows_memory_limit): every row of every view kept
// at once (one slab reading all of them) less what the host holds, or 0
// without cache_filtered_rows. For the disk check before a run.
std::uint64_t filtered_rows_disk_bound(const ScanGeometry& geometry, const FdkOptions& options);

// The most host memory the filtered rows of a scan of `geometry` can take
// with `options`: every row of every view where they fit the host budget
// (FdkOptions::filtered_rows_memory_limit, or the default), else the budget
// in whole row pairs; 0 without cache_filtered_rows. What the budget holds
// beyond this is never used, and recon gives it to a CPU device's slabs.
std::uint64_t filtered_rows_host_bound(const ScanGeometry& geometry, const FdkOptions& options);

FdkReport reconstruct_fdk(ProjectionSource& projections, const ScanGeometry& geometry, const VolumeGrid& grid,
                          const FdkOptions& options, const SlabSink& sink);

// The whole volume in memory (x fastest), for small volumes and tests.
std::vector<float> reconstruct_fdk_dense(ProjectionSource& projections, const ScanGeometry& geometry,
                                         const VolumeGrid& grid, const FdkOptions& options = {},
                                         FdkReport* report = nullptr);

struct DeviceInfo {
  int index = 0;
  std::string name;
  std::string platform;
  std::string version;
  bool is_gpu = false;
  std::uint64_t global_memory = 0;
  std::uint64_t max_allocation = 0;
  std::uint64_t local_memory = 0;
  unsigned compute_units = 0;
};
std::vector<DeviceInfo> list_devices();
// True when FdkOptions::native_cpu_backprojection takes effect on CPU
// devices here: the processor has AVX-512F (checked at run time).
bool native_backprojection_supported();

}  // namespace ivol::recon
