// ivol recon PROJECTIONS -o OUT.ivol: cone-beam FDK on OpenCL, written
// straight into an .ivol file slab by slab.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <utility>

#include "bricked_import.hpp"
#include "commands.hpp"
#include "disk_space.hpp"
#include "fixity.hpp"
#include "ivol/error.hpp"
#include "ivol/metadata.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/preview.hpp"
#include "ivol/structure_stream.hpp"
#include "ivol/structures.hpp"
#include "ivol_io.hpp"
#include "mpi_exchange.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "recon_budget.hpp"
#include "recon_built_slabs.hpp"
#include "recon_built_structure.hpp"
#include "recon_slabs.hpp"
#include "report.hpp"
#include "scan_input.hpp"
#include "signal_cleanup.hpp"

namespace ivol::cli {
namespace {

struct ReconSettings {
  ScanSettings scan;
  std::string output;
  std::string size;
  std::string voxel;  // S or SX,SY,SZ mm
  std::string origin;
  std::string window = "ram-lak";
  double cutoff = 1.0;
  std::vector<int> devices;
  std::uint64_t device_memory_mib = 0;
  std::uint32_t slab_slices = 0;
  std::string encoding = "binary16";
  std::string format_version = "1.3";
  std::string keep;
  std::string structure;
  std::string threshold = "otsu";
  std::string refine = "detection";
  unsigned margin = 2;
  std::uint32_t nested_cell = 16;
  unsigned preview_factor = 0;   // 0: the rule's own (2 for detection, 4 for the preview rule and --keep)
  std::uint64_t memory_mib = 0;  // 0: memory_budget's default
  MemoryBudget memory;           // what the run uses (set when it starts)
  std::string temp_dir;          // the octree writer's spill file (--temp-dir)
  bool no_disk_check = false;
  bool json = false;
  bool force = false;
};

// Gives the heap's free memory back to the system between phases: glibc
// keeps what a phase freed (the preview's cell layers, the generator's
// parts) and, its mmap threshold raised by the first large free, serves
// later large buffers from the heap, so RSS kept a phase's peak (issue 23,
// bench/RESULTS.md).
void return_free_memory() {
#if defined(__GLIBC__)
  ::malloc_trim(0);
#endif
}

// One size for every axis or one per axis (x, y, z: z along the rotation axis).
recon::Vec3 parse_voxel(const std::string& text) {
  const std::array<double, 3> voxel = parse_triple(text, "--voxel", true);
  for (double v : voxel)
    if (!(v > 0) || !std::isfinite(v))
      throw UsageError("--voxel", "'" + text + "': every voxel size must be a positive number of mm");
  return {voxel[0], voxel[1], voxel[2]};
}

nlohmann::json voxel_json(const recon::VolumeGrid& grid) {
  const recon::Vec3& v = grid.voxel_size;
  if (v[0] == v[1] && v[1] == v[2]) return v[0];
  return nlohmann::json::array({v[0], v[1], v[2]});
}

// A quarter of --memory: the writer's slab, the filtered rows and (on CPU
// devices) the device's slabs take one each.
std::uint64_t memory_share(const ReconSettings& s) { return s.memory.bytes / 4; }

// Each part's peak host memory (or temporary disk), for the report.
nlohmann::json memory_json(const ReconSettings& s, const recon::FdkReport& fdk, std::size_t devices) {
  return {{"budget_bytes", s.memory.bytes},
          {"budget_rule", s.memory.rule},
          {"device_slab_bytes", fdk.device_bytes_per_slab * devices},
          {"filtered_rows_host_bytes", fdk.filtered_rows_host_bytes},
          {"filtered_rows_disk_bytes", fdk.filtered_rows_disk_bytes},
          {"writer_slab_budget_bytes", memory_share(s)}};
}

// A dense run's writer: import_to_ivol's options for the reconstruction.
convert::ImportOptions dense_import_options(const ReconSettings& s) {
  convert::ImportOptions import;
  // What convert would write for float32 samples as binary16: a bricked grid
  // (bricked_import.hpp), an octree with --keep, float32 or format 1.2.
  // Distributed, the ranks make the same file (recon_built_slabs.hpp).
  import.structure = convert::StructureChoice::Auto;
  import.encoding = parse_encoding(s.encoding);
  import.framed_blocks = s.format_version == "1.3";
  import.slab_budget_bytes = memory_share(s);
  import.layer_budget_bytes = memory_share(s);
  import.memory_bytes = s.memory.bytes;  // the writer's own checks, by the same budget
  import.temp_directory = s.temp_dir;
  import.check_disk_space = false;  // checked before the reconstruction
  return import;
}

// A bricked grid's layer holds its values (16-bit, or float32) and, at worst, as many
// bytes of encoded bricks: at 2048² a layer of 32 slices needs 1 GiB, more
// than the writer's quarter of a 2 GiB --memory. Where it does not fit the
// quarter, the layer takes what the filtered rows leave unused (`spare`), up
// to its samples read 8 slices at a time; returns what it takes beyond the
// quarter (the CPU devices' slabs do without it) and whether the output is
// a bricked grid.
std::pair<std::uint64_t, bool> take_layer_budget(const recon::VolumeGrid& grid, convert::ImportOptions& import,
                                                 std::uint64_t spare) {
  const convert::DenseVolume shape = convert::float_volume_of(grid);
  const ValueEncoding encoding = *import.encoding;
  convert::ImportReport choice;
  if (convert::choose_bricked(shape, import, encoding, choice)) return {0, true};
  const std::uint64_t share = import.layer_budget_bytes;
  import.layer_budget_bytes = share + spare;
  if (!convert::choose_bricked(shape, import, encoding, choice)) {
    import.layer_budget_bytes = share;
    return {0, false};
  }
  const std::uint32_t layer = std::min<std::uint32_t>(shape.dims[2], 1u << import.brick_log2);
  import.layer_budget_bytes = std::clamp(convert::bricked_layer_bytes(shape, import, encoding, std::min(layer, 8u)),
                                         convert::bricked_layer_bytes(shape, import, encoding, 1), share + spare);
  return {import.layer_budget_bytes - share, true};
}

recon::VolumeGrid make_grid(const ReconSettings& s) {
  if (s.size.empty() || s.voxel.empty())
    throw UsageError(s.size.empty() ? "--size" : "--voxel",
                     "--size and --voxel are required (the scan's files do not propose a grid)");
  recon::VolumeGrid grid;
  const std::array<double, 3> size = parse_triple(s.size, "--size", true);
  for (int a = 0; a < 3; ++a) {
    if (!(size[a] >= 1) || size[a] != std::floor(size[a]) || size[a] > 1e6)
      throw UsageError("--size", "'" + s.size + "' is not N or X,Y,Z voxels (1 to 10^6)");
    grid.size[a] = static_cast<std::uint32_t>(size[a]);
  }
  grid = recon::VolumeGrid::centred(grid.size, parse_voxel(s.voxel));
  if (!s.origin.empty()) grid.origin = parse_triple(s.origin, "--origin", false);
  return grid;
}

void check_size(const std::string& value) {
  ReconSettings probe;
  probe.size = value;
  probe.voxel = "1";
  make_grid(probe);
}

void check_voxel(const std::string& value) { parse_voxel(value); }

void check_threshold(const std::string& value) {
  if (value != "otsu") parse_number(value, "--threshold");
}

// Every file the reconstruction reads (projections, flat and dark fields, the
// geometry), each with its role for provenance.sources.
void scan_inputs(const ScanSettings& scan, std::vector<std::string>& inputs, std::vector<nlohmann::json>& roles) {
  const auto add = [&](const std::string& path, const char* role) {
    inputs.push_back(path);
    roles.push_back(nlohmann::json{{"role", role}});
  };
  add(scan.projections, "projections");
  for (const std::string& f : scan.flats) add(f, "flat");
  for (const std::string& f : scan.darks) add(f, "dark");
  if (!scan.geometry_xml.empty()) add(scan.geometry_xml, "geometry");
  for (const auto& [path, role] : scan_companion_files(scan)) {
    inputs.push_back(path);
    roles.push_back(nlohmann::json{{"role", role}});
  }
}

// --size and --voxel, else the grid the scan's files propose (a Nikon
// scan's VoxelsX/Y/Z and VoxelSizeX/Y/Z).
recon::VolumeGrid grid_of(ReconSettings& s, const OpenedScan& scan) {
  if (scan.has_grid && s.size.empty() && s.voxel.empty()) {
    auto text = [](double v) {
      std::ostringstream out;
      out.precision(17);
      out << v;
      return out.str();
    };
    s.size = std::to_string(scan.grid_size[0]) + "," + std::to_string(scan.grid_size[1]) + "," +
             std::to_string(scan.grid_size[2]);
    s.voxel = text(scan.grid_voxel[0]) + "," + text(scan.grid_voxel[1]) + "," + text(scan.grid_voxel[2]);
  }
  return make_grid(s);
}

constexpr recon::DetectionRule kDetection{};

std::string share_text(double share) {
  std::ostringstream text;
  text << share;
  return text.str();
}

// The rule in words, for provenance.
std::string refinement_rule(bool detection, unsigned factor) {
  const std::string cell = std::to_string(factor) + "^3";
  if (!detection)
    return "a " + cell + " cell is full resolution where the 1/" + std::to_string(factor) +
           " preview's value at its centre exceeds the threshold, or within the margin (in whole cells) of one "
           "that does";
  return "a " + cell + " cell is full resolution where the largest sample of a 1/" +
         std::to_string(factor > 2 ? factor / 2 : factor) + " reconstruction (one view in " +
         std::to_string(kDetection.thinning) + ", " + std::to_string(kDetection.thinning) + "x" +
         std::to_string(kDetection.thinning) +
         " pixels merged) within the margin of the cell, rounded up to binary16, exceeds the threshold";
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Each rank's share of a distributed run (docs/distributed.md).
nlohmann::json ranks_json(const std::vector<RankStats>& ranks) {
  nlohmann::json list = nlohmann::json::array();
  for (std::size_t r = 0; r < ranks.size(); ++r) {
    const RankStats& k = ranks[r];
    const double gups = k.backprojection > 0 ? static_cast<double>(k.voxel_updates) / k.backprojection * 1e-9 : 0.0;
    list.push_back({{"rank", r},
                    {"seconds", k.seconds},
                    {"backprojection_seconds", k.backprojection},
                    {"gups", gups},
                    {"voxel_updates", k.voxel_updates},
                    {"slabs_sent", k.slabs_sent},
                    {"bytes_sent", k.bytes_sent},
                    {"bytes_received", k.bytes_received},
                    {"slab_bytes_sent", k.slab_bytes_sent},
                    {"slab_bytes_received", k.slab_bytes_received},
                    {"slabs_built", k.slabs_built},
                    {"slices_built", k.slices_built},
                    {"build_seconds", k.build_seconds},
                    {"blocks_compressed", k.blocks_compressed},
                    {"compression_input_bytes", k.compression_input_bytes},
                    {"compression_output_bytes", k.compression_output_bytes},
                    {"compression_seconds", k.compression_seconds},
                    {"block_bytes_sent", k.block_bytes_sent},
                    {"block_bytes_received", k.block_bytes_received}});
  }
  return list;
}

// This rank's part of the report, before the bytes and compression that
// MpiRun::gather adds.
RankStats rank_stats(const recon::FdkReport& fdk, std::chrono::steady_clock::time_point start) {
  RankStats mine;
  mine.seconds = seconds_since(start);
  mine.backprojection = fdk.timings.backprojection;
  mine.voxel_updates = fdk.voxel_updates;
  return mine;
}

// After a distributed run whose ranks built their own slabs (dense or
// octree): rank 0 ends the shared compression, the others serve it until
// then; every rank's stats, with what it built, go to rank 0.
template <class Built>
std::vector<RankStats> gather_built(MpiRun& mpi, const Built& built, std::chrono::steady_clock::time_point start) {
  if (mpi.rank() == 0)
    mpi.end_compression();
  else
    mpi.serve_compression();
  RankStats mine = rank_stats(built.fdk, start);
  mine.slabs_built = built.slabs_built;
  mine.slices_built = built.slices_built;
  mine.build_seconds = built.build_seconds;
  return mpi.gather(mine);
}

// The run's throughput: each rank's updates over its own backprojection time, summed.
double total_gups(const std::vector<RankStats>& ranks) {
  double gups = 0;
  for (const RankStats& k : ranks)
    if (k.backprojection > 0) gups += static_cast<double>(k.voxel_updates) / k.backprojection * 1e-9;
  return gups;
}

void print_ranks(const std::vector<RankStats>& ranks) {
  std::cerr << std::fixed << std::setprecision(2) << "ivol recon: " << ranks.size() << " ranks:";
  for (std::size_t r = 0; r < ranks.size(); ++r)
    std::cerr << (r ? ";" : "") << " rank " << r << " " << ranks[r].seconds << " s, sent "
              << human_bytes(ranks[r].bytes_sent) << " (" << ranks[r].slabs_sent << " slabs), built "
              << ranks[r].slabs_built << " slabs in " << ranks[r].build_seconds << " s, compressed "
              << ranks[r].blocks_compressed << " blocks";
  std::cerr << "\n";
}

// Where the structure needs full resolution: the preview and its need mask.
struct FoundObject {
  NeedMask mask;
  float otsu_threshold = 0.0F;
  float threshold = 0.0F;
  double seconds = 0.0;
  std::uint64_t preview_bytes = 0;  // preview values held at once
  std::uint64_t preview_spilled_bytes = 0;
  std::uint64_t preview_spilled_raw_bytes = 0;  // before the spool's compression
};

recon::DetectionMaskOptions detection_options(const ReconSettings& s, const recon::FdkOptions& fdk_options,
                                              unsigned factor, std::optional<float> given_threshold) {
  recon::DetectionMaskOptions options;
  options.rule = kDetection;
  options.rule.factor = factor;
  options.margin_voxels = s.margin;
  options.threshold = given_threshold;
  options.preview_memory = memory_share(s);
  options.temp_directory = fdk_options.temp_directory;  // where the filtered rows go
  return options;
}

// The refinement rule (docs/refinement.md). detection: each preview cell the
// largest sample of a 1/(factor/2) reconstruction within the margin of it,
// against a share of Otsu's threshold that covers the preview's blur; the
// margin is applied while pooling, so the need mask adds none. The preview is
// pooled and thresholded layer by layer, holding the cell layers within the
// quarter of --memory left for the preview and the value window, the rest in
// a temporary file (recon::detect_need_mask). preview (the rule before issue
// 18): each cell its centre's value on a 1/factor preview, half of Otsu's
// threshold, the margin in whole cells; that preview (1/64 of the dense
// volume at the default factor 4) is held whole.
FoundObject find_object(const ReconSettings& s, const recon::VolumeGrid& grid, const recon::FdkOptions& fdk_options,
                        OpenedScan& scan, bool detection, unsigned factor, std::optional<float> given_threshold) {
  FoundObject found;
  if (detection) {
    const recon::DetectionMaskOptions options = detection_options(s, fdk_options, factor, given_threshold);
    // The writer's quarter of --memory is not in use before the structure
    // exists: the preview's CPU devices take it beside their own, for
    // thicker slabs (bench/RESULTS.md, "Thin dense slabs on the CPU").
    recon::FdkOptions preview_fdk = fdk_options;
    if (preview_fdk.cpu_device_memory_limit > 0) preview_fdk.cpu_device_memory_limit += memory_share(s);
    recon::DetectionMask detected =
        recon::detect_need_mask(*scan.projections, scan.geometry, preview_fdk, grid, options);
    found.mask = std::move(detected.mask);
    found.otsu_threshold = detected.otsu_threshold;
    found.threshold = detected.threshold;
    found.seconds = detected.seconds;
    found.preview_bytes = detected.peak_preview_bytes;
    found.preview_spilled_bytes = detected.spilled_bytes;
    found.preview_spilled_raw_bytes = detected.spilled_raw_bytes;
    return found;
  }
  const recon::Preview preview =
      recon::reconstruct_preview(*scan.projections, scan.geometry, fdk_options, grid, factor);
  found.otsu_threshold = preview.otsu_threshold;
  found.threshold = given_threshold ? *given_threshold : 0.5F * preview.otsu_threshold;
  found.seconds = preview.seconds;
  found.preview_bytes = preview.values.size() * sizeof(float);
  const Dims full{grid.size[0], grid.size[1], grid.size[2]};
  const Dims low{preview.grid.size[0], preview.grid.size[1], preview.grid.size[2]};
  found.mask = need_mask_from_low_resolution(preview.values.data(), low, factor, full, found.threshold, s.margin);
  return found;
}

// The paper's pipeline: a low-resolution preview finds the object, the
// structure is generated from it, the FDK backprojects into the structure's
// voxels only, and the structure is written as an .ivol file of its kind
// while the slabs finish. Host memory, by quarters of --memory (README,
// "ivol recon"): the writer's slab, the filtered detector rows (the rest in
// a temporary file), on CPU devices the device's buffers, and the detection
// preview (cells and Otsu's samples beyond it in temporary files; its ring
// and the 1-bit need mask refused when they do not fit) and then the
// structure's value window (slabs thinned to fit it). Beyond --memory: the
// structure's bricks (48 bytes each) and the FDK's index of them, the task
// lists of the slabs in flight. Never the dense volume nor all the values.
int run_structure(const ReconSettings& s, const GlobalOptions& global, const recon::VolumeGrid& grid,
                  const recon::FdkOptions& fdk_options, OpenedScan& scan, recon::FdkReconstructor& reconstructor,
                  Metadata metadata, const std::function<void(Metadata&)>& complete_metadata,
                  std::chrono::steady_clock::time_point start, MpiRun* mpi) {
  StructureKind kind{};
  parse_structure(s.structure, kind);
  const bool detection = s.refine == "detection";
  const unsigned factor = s.preview_factor ? s.preview_factor : detection ? kDetection.factor : 4;
  std::optional<float> given_threshold;
  if (s.threshold != "otsu") given_threshold = static_cast<float>(parse_number(s.threshold, "--threshold"));
  FoundObject found = find_object(s, grid, fdk_options, scan, detection, factor, given_threshold);
  return_free_memory();
  const float threshold = found.threshold;
  auto generation_start = std::chrono::steady_clock::now();
  GenerationOptions generation;
  generation.nested_cell = s.nested_cell;
  std::unique_ptr<VoxelStructure> structure = generate_structure(kind, found.mask, generation);
  const double generating = seconds_since(generation_start);
  // The structure holds what the reconstruction needs of the mask.
  const std::uint64_t need_mask_bytes = found.mask.memory_bytes();
  found.mask = NeedMask{};
  return_free_memory();
  if (!global.quiet && (!mpi || mpi->rank() == 0))
    std::cerr << std::fixed << std::setprecision(1) << "ivol recon: preview " << found.seconds << " s (held "
              << human_bytes(found.preview_bytes) << ", spilled " << human_bytes(found.preview_spilled_bytes)
              << " compressed from " << human_bytes(found.preview_spilled_raw_bytes) << "); structure generated in "
              << generating << " s: " << structure->bricks().size() << " bricks ("
              << human_bytes(structure->bricks().memory_bytes()) << "), " << structure->voxel_count() << " voxels\n";

  metadata.provenance["reconstruction"]["structure"] = {
      {"kind", s.structure},
      {"refinement", s.refine},
      {"refinement_rule", refinement_rule(detection, factor)},
      {"threshold", threshold},
      {"threshold_method", s.threshold != "otsu" ? "given"
                           : detection           ? share_text(kDetection.otsu_share) + " of Otsu's on the samples"
                                                 : "half of Otsu's on the preview"},
      {"otsu_threshold", found.otsu_threshold},
      {"margin", s.margin},
      {"preview_factor", factor},
      {"voxels", structure->voxel_count()}};
  metadata.voxel_size = grid.voxel_size;
  metadata.origin = grid.origin;
  metadata.unit = "mm";
  // Distributed octrees: each rank fills and builds the writer's slabs it
  // owns (recon_built_structure.hpp). The grids: the ranks reconstruct
  // slabs for rank 0, which fills and writes, and share the compression.
  const bool distributed_build = mpi && kind == StructureKind::Octree;
  if (mpi && mpi->rank() != 0 && !distributed_build) {
    // A rank of a distributed run other than 0: its slabs go to rank 0, which
    // writes and reports; then it compresses blocks for rank 0's writer.
    StructureValueWindow unused(*structure);
    const recon::FdkReport mine = reconstructor.reconstruct_structure(grid, *structure, unused, {});
    mpi->serve_compression();
    mpi->gather(rank_stats(mine, start));
    return kExitOk;
  }
  // The structure's bricks (16 bytes each, and the FDK's and the writer's
  // index of them, about 13 bytes a brick) count against --memory: the device slabs on
  // CPU devices and the writer's slab share what they leave with the
  // filtered rows and the value window, a quarter each but no less than a
  // sixteenth of --memory each (below that, slabs would be too thin to be
  // worth it; the run then goes over --memory, which the notes say). The
  // value window keeps its quarter (the preview's, the preview being done):
  // at 1152³ it needed 125 MiB with one-slice slabs (bench/RESULTS.md).
  const std::uint64_t structure_held = structure->bricks().memory_bytes() + structure->bricks().size() * 13;
  const std::uint64_t left = s.memory.bytes > structure_held ? s.memory.bytes - structure_held : 0;
  const std::uint64_t part = std::min(memory_share(s), std::max(left / 4, s.memory.bytes / 16));
  // The device's slabs get `part` alone here, not what the filtered rows'
  // quarter cannot use: the rows keep their quarter while the other parts
  // shrink to `part`, so that spare is not in the budget (with it, the
  // 2048³ octree's structure FDK peaked at 3.11 GB RSS against 2.89).
  reconstructor.set_cpu_device_memory_limit(part);
  if (!global.quiet && 4 * part > left)
    std::cerr << "ivol recon: the structure's " << human_bytes(structure_held) << " leave " << human_bytes(left)
              << " of --memory; its parts take " << human_bytes(part) << " each, going over --memory by "
              << human_bytes(4 * part + structure_held - s.memory.bytes) << "\n";
  StreamingOptions options;
  options.build.encoding = parse_encoding(s.encoding);
  options.slab_budget_bytes = part;
  options.spill_directory = s.temp_dir;
  // The other ranks take a share of the compression once their slabs are
  // sent; the writer calls it on this (the MPI) thread.
  if (mpi) options.write.encoder = mpi->block_encoder();
  options.write.framed_blocks = s.format_version == "1.3";
  recon::FdkReconstructor::ValueWindowBound window;
  window.memory_limit = memory_share(s);
  recon::FdkReport fdk;
  StreamingResult written;
  std::uint64_t writer_index = 0;
  double writing = 0;
  double writing_during_fdk = 0;  // the writer works inside the FDK's slab hand-over
  double building = 0;            // distributed: filling and building rank 0's own slabs
  std::uint64_t value_window_peak = 0;
  std::vector<RankStats> ranks;
  if (distributed_build) {
    convert::DistributedStructureOptions distributed;
    distributed.streaming = options;
    distributed.most_slab_slices = s.slab_slices;
    distributed.value_window_bytes = window.memory_limit;
    distributed.metadata = metadata;
    distributed.complete = complete_metadata;
    distributed.every_slab_received = [&] { mpi->every_slab_received(); };
    const convert::DistributedStructureBuild built = convert::reconstruct_structure_distributed(
        reconstructor, grid, *structure, s.output, distributed, *mpi->exchange());
    ranks = gather_built(*mpi, built, start);
    if (mpi->rank() != 0) return kExitOk;
    fdk = built.fdk;
    written = built.written;
    writing = built.writing_seconds;
    building = built.build_seconds;
    value_window_peak = built.value_window_peak_bytes;
    writing_during_fdk = built.during_fdk_seconds;
    window.writer_slab_slices = built.slab_slices;
  } else {
    // Without sources to digest the metadata is complete here, and a grid's
    // file begins with it (spec §15); the digests come after the values, so
    // then it comes last (an early metadata block, stream 6, is not written).
    std::optional<StructureStreamWriter> writer_storage;
    if (complete_metadata)
      writer_storage.emplace(*structure, s.output, options);
    else
      writer_storage.emplace(*structure, s.output, options, metadata);
    StructureStreamWriter& writer = *writer_storage;
    StructureValueWindow values(*structure);
    // The values in flight take their part (the preview's quarter once the
    // preview is done, less the structure's share): slabs are cut thinner
    // until they fit it.
    window.writer_slab_slices = writer.slab_slices();
    writer_index = writer.index_bytes();
    fdk = reconstructor.reconstruct_structure(
        grid, *structure, values,
        [&](std::uint32_t z_complete) {
          const auto began = std::chrono::steady_clock::now();
          writer.write_ready(z_complete, values);
          writing_during_fdk += seconds_since(began);
        },
        window);
    if (mpi) mpi->every_slab_received();  // the rest of the file is compressed on every rank
    if (complete_metadata) complete_metadata(metadata);
    written = writer.finish(metadata, values);
    writing = written.write.seconds;
    value_window_peak = values.peak_bytes();
    if (mpi) {
      mpi->end_compression();
      ranks = mpi->gather(rank_stats(fdk, start));
    }
  }
  double gups = fdk.gups();
  std::uint64_t voxel_updates = fdk.voxel_updates;  // this process's own slabs
  if (mpi) {
    gups = total_gups(ranks);
    voxel_updates = 0;
    for (const RankStats& k : ranks) voxel_updates += k.voxel_updates;
  }
  const double total = seconds_since(start);
  const StructureMemory memory = structure->memory();
  nlohmann::json report = {
      {"output", s.output},
      {"structure", s.structure},
      {"size", {grid.size[0], grid.size[1], grid.size[2]}},
      {"voxel_mm", voxel_json(grid)},
      {"views", scan.geometry.view_count()},
      {"devices", reconstructor.device_names()},
      {"threshold", threshold},
      {"structure_voxels", structure->voxel_count()},
      {"voxel_reduction", static_cast<double>(grid.voxel_count()) / static_cast<double>(structure->voxel_count())},
      {"structure_bytes", memory.total()},
      {"dense_float32_bytes", grid.voxel_count() * 4},
      {"file_bytes", written.write.file_bytes},
      {"temp_bytes", written.spill_bytes},
      {"peak_value_bytes", value_window_peak},
      {"rows_filtered", fdk.rows_filtered},
      {"gups", gups},
      {"voxel_updates", voxel_updates},
      {"seconds",
       {{"total", total},
        {"preview", found.seconds},
        {"generation", generating},
        {"reading", fdk.timings.reading},
        {"filtering", fdk.timings.filtering},
        {"backprojection", fdk.timings.backprojection},
        {"reconstruction", fdk.timings.total - writing_during_fdk},
        {"writing", writing}}}};
  report["memory"] = memory_json(s, fdk, reconstructor.device_names().size());
  report["memory"]["preview_bytes"] = found.preview_bytes;
  report["memory"]["preview_spilled_bytes"] = found.preview_spilled_bytes;
  report["memory"]["preview_spilled_raw_bytes"] = found.preview_spilled_raw_bytes;
  report["memory"]["value_window_bytes"] = value_window_peak;
  report["memory"]["value_window_model_bytes"] = fdk.value_window_model_bytes;
  report["memory"]["value_window_budget_bytes"] = window.memory_limit;
  if (distributed_build) report["seconds"]["building"] = building;
  report["slab_slices"] = fdk.slab_slices;
  report["memory"]["need_mask_bytes"] = need_mask_bytes;
  report["memory"]["structure_held_bytes"] = structure_held;
  report["memory"]["reconstruction_part_bytes"] = part;
  report["memory"]["writer_slab_budget_bytes"] = part;
  report["memory"]["writer_index_bytes"] = writer_index;
  report["memory"]["structure_bricks_bytes"] = structure->bricks().memory_bytes();
  report["memory"]["slab_index_bytes"] = fdk.slab_index_bytes;
  report["memory"]["slab_tasks_peak_bytes"] = fdk.slab_tasks_peak_bytes;
  report["memory"]["slab_tasks_model_bytes"] = fdk.slab_tasks_model_bytes;
  if (mpi) report["ranks"] = ranks_json(ranks);
  if (s.json) {
    std::cout << report.dump(2) << "\n";
  } else if (!global.quiet) {
    std::cerr << std::fixed << std::setprecision(2) << "ivol recon: " << s.structure << " of "
              << structure->voxel_count() << " voxels ("
              << static_cast<double>(grid.voxel_count()) / static_cast<double>(structure->voxel_count())
              << "x fewer than " << grid.size[0] << "x" << grid.size[1] << "x" << grid.size[2] << ") in " << total
              << " s (preview " << found.seconds << " s, generation " << generating << " s, FDK "
              << fdk.timings.total - writing_during_fdk << " s, writing " << writing << " s); " << s.output << ": "
              << human_bytes(written.write.file_bytes) << "\n";
    if (mpi) print_ranks(ranks);
  }
  return kExitOk;
}

}  // namespace

Runner add_recon_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("recon", "Reconstruct a circular cone-beam scan (FDK on OpenCL) into an .ivol file");
  auto s = std::make_shared<ReconSettings>();
  add_scan_options(cmd, s->scan);
  cmd->add_option("-o,--output", s->output, "Output .ivol file")->required();
  cmd->add_flag("-f,--force", s->force, "Replace the output if it exists");
  auto* volume = cmd->add_option_group("volume");
  volume->add_option("--size", s->size, "N or X,Y,Z voxels (default: the grid a Nikon .xtekct file proposes)")
      ->check(checked(check_size));
  volume
      ->add_option("--voxel", s->voxel,
                   "Voxel size in mm: S, or SX,SY,SZ (z along the rotation axis; default: as --size)")
      ->check(checked(check_voxel));
  volume->add_option("--origin", s->origin, "X,Y,Z of voxel 0's centre, mm (default: volume centred on the axis)")
      ->check(checked([](const std::string& v) { parse_triple(v, "--origin", false); }));
  auto* fdk = cmd->add_option_group("filter and devices");
  fdk->add_option("--window", s->window, "Ramp window: ram-lak, shepp-logan, cosine, hamming, hann")
      ->check(CLI::IsMember({"ram-lak", "shepp-logan", "cosine", "hamming", "hann"}))
      ->capture_default_str();
  fdk->add_option("--cutoff", s->cutoff, "Cut-off frequency as a fraction of Nyquist, (0, 1]")
      ->check(number_in(0, 1, true))
      ->capture_default_str();
  fdk->add_option("--device", s->devices, "OpenCL device index (see ivol devices); repeat for several")
      ->check(whole_number());
  fdk->add_option("--device-memory", s->device_memory_mib,
                  "MiB of device memory to use (default: 80 % of it on GPUs, a quarter of --memory on CPU devices)")
      ->check(mebibytes());
  fdk->add_option("--slab-slices", s->slab_slices,
                  "Most slices per slab (default: as many as fit the device; under mpirun, at most the volume's "
                  "depth over the ranks; under mpirun without --structure, also the writer's slabs that the ranks "
                  "build, a power of two)")
      ->check(whole_number());
  auto* out = cmd->add_option_group("output");
  out->add_option("--encoding", s->encoding, "binary16 or float32")
      ->check(CLI::IsMember({"binary16", "float32"}))
      ->capture_default_str();
  out->add_option("--format-version", s->format_version,
                  "1.3: framed blocks, salvageable when cut; 1.2: for readers older than 1.3")
      ->check(CLI::IsMember({"1.3", "1.2"}))
      ->capture_default_str();
  out->add_option("--keep", s->keep,
                  "threshold=T|otsu,margin=M: full resolution only around the object (otsu: from a preview)")
      ->check(checked([](const std::string& v) { parse_keep(v, "--keep"); }));
  auto* paper = cmd->add_option_group("inhomogeneous (Betz et al.)");
  paper
      ->add_option("--structure", s->structure,
                   "Reconstruct straight into octree, nested, rectilinear or regular: full resolution only "
                   "around the object, found on a low-resolution preview")
      ->check(CLI::IsMember({"octree", "nested", "rectilinear", "regular"}));
  paper
      ->add_option("--threshold", s->threshold,
                   "With --structure: the object's threshold on the preview, a value or otsu (" +
                       share_text(kDetection.otsu_share) +
                       " of Otsu's on the detection samples; half of Otsu's with --refine preview)")
      ->check(checked(check_threshold))
      ->capture_default_str();
  paper
      ->add_option("--refine", s->refine,
                   "With --structure: which cells get full resolution. detection: a cell whose largest sample of a "
                   "1/(factor/2) reconstruction within --margin voxels of it exceeds --threshold (keeps walls and "
                   "wires one voxel thin; docs/refinement.md); preview: a cell whose 1/factor preview value at its "
                   "centre does, grown by --margin in whole cells (the rule before 2026-12)")
      ->check(CLI::IsMember({"detection", "preview"}))
      ->capture_default_str();
  paper->add_option("--margin", s->margin, "With --structure: full-resolution voxels kept around the object")
      ->check(whole_number())
      ->capture_default_str();
  paper->add_option("--nested-cell", s->nested_cell, "With --structure nested: cell edge in voxels (power of two)")
      ->check(whole_number())
      ->capture_default_str();
  out->add_option("--preview-factor", s->preview_factor,
                  "Edge in voxels of the cells the preview marks (a power of two; default 2 with --refine "
                  "detection, 4 with --refine preview and --keep ...otsu)")
      ->check(CLI::IsMember({2, 4, 8, 16, 32}));
  out->add_option("--memory", s->memory_mib,
                  "About how many MiB of host memory the run may use (default: half of the memory cgroup's limit "
                  "when one is set, else half of MemAvailable, at least 256 MiB; printed in the notes and --json): "
                  "a quarter each for the writer's slab (a bricked grid's layer, with what the rows leave if it "
                  "must), the filtered detector rows (the rest go to a temporary "
                  "file, see --temp-dir), on CPU devices the device's slabs and, with --structure, the detection "
                  "preview (its cells and the samples for Otsu's threshold, the rest to a temporary file; the need "
                  "mask at 1 bit per cell) and then the structure's value window (slabs are cut thinner to fit)")
      ->check(mebibytes());
  out->add_option(
      "--temp-dir", s->temp_dir,
      "Directory of the octree writer's temporary spill file and of the filtered detector rows and the "
      "detection preview's cells beyond their share of --memory (default: $TMPDIR, else the output's directory)");
  out->add_flag("--no-disk-check", s->no_disk_check,
                "Skip the check that the output's and the spill file's disks have the room the run is estimated to "
                "need");
  cmd->add_flag("--json", s->json, "Print the report as JSON on stdout");

  // mpi: this process is one rank of a distributed run (mpirun), or null.
  auto run = [s, &global](MpiRun* mpi) {
    const auto start = std::chrono::steady_clock::now();
    s->memory = memory_budget(s->memory_mib);
#if defined(__GLIBC__)
    // Large buffers always from mmap, so that freeing them returns them
    // (glibc's threshold otherwise rises to the largest freed, up to 32 MiB).
    ::mallopt(M_MMAP_THRESHOLD, 1 << 20);
#endif
    if (!s->structure.empty() && !s->keep.empty())
      throw UsageError("--keep", "--keep and --structure: choose one (--structure uses --threshold)");
    if (lower_extension(s->output) != ".ivol") throw UsageError("-o", "'" + s->output + "' is not an .ivol name");
    std::vector<std::string> inputs;
    std::vector<nlohmann::json> roles;
    scan_inputs(s->scan, inputs, roles);
    std::vector<std::string> input_paths = inputs;  // folders too
    for (const std::string& i : inputs)
      for (const std::string& f : input_files(i)) input_paths.push_back(f);
    // Distributed, rank 0 writes the file.
    const bool writes = !mpi || mpi->rank() == 0;
    if (writes) check_output(s->output, "-o", input_paths, s->force);
    if (writes) remove_temporaries_on_signal(s->output);
    // Hashed on a thread of its own while the reconstruction runs.
    std::shared_ptr<SourceDigests> digests;
    if (writes) digests = std::make_shared<SourceDigests>(inputs, roles);
    if (s->size.empty() != s->voxel.empty())
      throw UsageError(s->size.empty() ? "--size" : "--voxel", "--size and --voxel go together");
    // libhdf5's child process (HDF5 projections) may allocate --memory too.
    s->scan.memory_bytes = s->memory_mib << 20;
    OpenedScan scan = open_scan(s->scan);
    const recon::VolumeGrid grid = grid_of(*s, scan);
    recon::FdkOptions options;
    options.window = recon::parse_ramp_window(s->window);
    options.cutoff = s->cutoff;
    options.devices = s->devices;
    options.device_memory_limit = s->device_memory_mib << 20;
    options.max_slab_slices = s->slab_slices;
    // One budget, --memory, shared out (README, "ivol recon"): a
    // quarter each for the writer's slab, the filtered detector rows (the
    // rest of them go to a temporary file) and, on CPU devices, whose memory
    // is the host's, the device's slabs; the preview and the structure's
    // value window take the last quarter. A dense run has neither, so its
    // CPU devices take that quarter too: their slabs are twice as thick,
    // and a thin slab costs the native backprojector far more per voxel
    // (bench/RESULTS.md, "Thin dense slabs on the CPU").
    // What the rows' quarter holds beyond every filtered row of the scan
    // (at 2048³ from 120 views of 384², 71 MB of its 512 MiB) goes to the CPU
    // devices' slabs as well.
    options.filtered_rows_memory_limit = memory_share(*s);
    const std::uint64_t rows_spare =
        memory_share(*s) - std::min(memory_share(*s), recon::filtered_rows_host_bound(scan.geometry, options));
    convert::ImportOptions import = dense_import_options(*s);
    const auto [layer_extra, bricked_output] = s->structure.empty() && s->keep.empty()
                                                   ? take_layer_budget(grid, import, rows_spare)
                                                   : std::pair<std::uint64_t, bool>{0, false};
    options.cpu_device_memory_limit =
        (s->structure.empty() ? 2 * memory_share(*s) : memory_share(*s)) + rows_spare - layer_extra;
    // Filtered rows beyond their share go where the writer's spill goes:
    // --temp-dir, else $TMPDIR, else the output's directory.
    options.temp_directory = s->temp_dir;
    const char* tmpdir = std::getenv("TMPDIR");
    if (options.temp_directory.empty() && (tmpdir == nullptr || *tmpdir == '\0')) {
      const std::filesystem::path parent = std::filesystem::path(s->output).parent_path();
      options.temp_directory = parent.empty() ? "." : parent.string();
    }
    if (mpi) options.exchange = mpi->exchange();
    // Distributed, rank 0 writes the file and reports; the others only reconstruct.
    const bool root = !mpi || mpi->rank() == 0;
    const bool quiet = global.quiet || !root;
    // Before any work (the preview included): every file the run writes must
    // find room, the output and each temporary file (recon_budget.hpp).
    if (writes && !s->no_disk_check) {
      std::optional<recon::DetectionMaskOptions> detection;
      if (!s->structure.empty() && s->refine == "detection")
        detection =
            detection_options(*s, options, s->preview_factor ? s->preview_factor : kDetection.factor, std::nullopt);
      const ReconDiskNeeds needs = recon_disk_needs(
          scan.geometry, grid, options, detection, parse_encoding(s->encoding),
          (s->structure.empty() && !bricked_output) || s->structure == "octree", s->output, s->temp_dir);
      convert::require_disk_space(needs.reconstruction);
      convert::require_disk_space(needs.preview);
    }
    if (!quiet)
      std::cerr << "ivol recon: memory budget " << human_bytes(s->memory.bytes) << ": " << s->memory.rule << "\n";
    // Distributed and dense, each rank reconstructs whole writer slabs by
    // itself (recon_built_slabs.hpp); the preview is still shared.
    recon::FdkOptions reconstructor_options = options;
    // So do the ranks of a distributed octree (recon_built_structure.hpp).
    if (mpi && (s->structure.empty() || s->structure == "octree")) reconstructor_options.exchange = nullptr;
    recon::FdkReconstructor reconstructor(*scan.projections, scan.geometry, reconstructor_options);
    for (const std::string& w : scan.warnings)
      if (!quiet) std::cerr << "ivol recon: warning: " << w << "\n";
    for (const std::string& w : reconstructor.warnings())
      if (!quiet) std::cerr << "ivol recon: warning: " << w << "\n";
    for (const std::string& n : scan.notes)
      if (!quiet) std::cerr << "ivol recon: " << n << "\n";

    double preview_seconds = 0.0;
    const unsigned keep_factor = s->preview_factor ? s->preview_factor : 4;
    if (!s->keep.empty()) {
      convert::KeepRule rule = parse_keep(s->keep, "--keep");
      if (rule.otsu) {
        // The paper's way: a quick low-resolution reconstruction finds the
        // object; its Otsu threshold then marks the full-resolution region.
        const recon::Preview preview =
            recon::reconstruct_preview(*scan.projections, scan.geometry, options, grid, keep_factor);
        rule.otsu = false;
        rule.threshold = preview.otsu_threshold;
        preview_seconds = preview.seconds;
      }
      import.keep = rule;
    }
    Metadata& m = import.metadata;
    m.provenance = default_provenance();
    m.provenance["command"] = global.command_line;
    if (digests) import.complete_metadata = SourceDigests::filler(digests);
    m.provenance["reconstruction"] = {{"algorithm", "FDK"},
                                      {"window", s->window},
                                      {"cutoff", s->cutoff},
                                      {"scan", reconstructor.short_scan() ? "short (Parker weights)" : "full"},
                                      {"devices", reconstructor.device_names()},
                                      {"acquisition", scan.description}};
    if (import.keep) {
      m.provenance["reconstruction"]["keep"] = {
          {"threshold", import.keep->threshold},
          {"margin", import.keep->margin},
          {"method", s->keep.find("otsu") != std::string::npos
                         ? "otsu on a 1/" + std::to_string(keep_factor) + " preview"
                         : "given"}};
    }
    m.quantity = "linear_attenuation";
    m.value_unit = "1/mm";
    import.progress = progress_bar("ivol recon", quiet || s->json);

    if (!s->structure.empty()) {
      return run_structure(*s, global, grid, options, scan, reconstructor, import.metadata, import.complete_metadata,
                           start, mpi);
    }
    convert::ImportReport written;
    recon::FdkTimings t;
    double gups = 0.0;
    double reconstruction = 0.0;
    double writing = 0.0;
    double building = 0.0;  // distributed: rank 0's own slabs' subtrees
    std::vector<RankStats> ranks;
    recon::FdkReport fdk_totals;  // rows filtered and memory peaks
    if (!mpi) {
      convert::ReconstructionSlabs slabs(reconstructor, grid, import.keep ? import.keep->margin : 0);
      written = convert::import_to_ivol(slabs, s->output, import);
      t = slabs.timings();
      gups = slabs.gups();
      reconstruction = slabs.read_seconds();
      writing = written.seconds - slabs.read_seconds();
      fdk_totals.rows_filtered = slabs.rows_filtered();
      fdk_totals.filtered_rows_host_bytes = slabs.filtered_rows_host_bytes();
      fdk_totals.filtered_rows_disk_bytes = slabs.filtered_rows_disk_bytes();
      fdk_totals.device_bytes_per_slab = slabs.device_bytes_per_slab();
    } else {
      // Distributed: each rank reconstructs whole writer slabs, builds their
      // subtrees and sends them to rank 0, which writes them in z order.
      // The other ranks then compress blocks for rank 0's writer.
      import.encoder = mpi->block_encoder();
      const convert::DistributedBuild built =
          convert::reconstruct_distributed(reconstructor, grid, s->output, import, *mpi->exchange(), s->slab_slices,
                                           [&] { mpi->every_slab_received(); });
      ranks = gather_built(*mpi, built, start);
      if (!root) return kExitOk;
      written = built.written;
      t = built.fdk.timings;
      fdk_totals = built.fdk;
      gups = total_gups(ranks);
      reconstruction = built.reconstruction_seconds;
      building = built.build_seconds;
      writing = built.writing_seconds;
    }
    const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    nlohmann::json report = {{"output", s->output},
                             {"size", {grid.size[0], grid.size[1], grid.size[2]}},
                             {"voxel_mm", voxel_json(grid)},
                             {"views", scan.geometry.view_count()},
                             {"devices", reconstructor.device_names()},
                             {"file_bytes", written.file_bytes},
                             {"structure", written.structure},
                             {"structure_reason", written.structure_reason},
                             {"temp_bytes", written.temp_bytes},
                             {"kept_voxels", written.kept_voxels},
                             {"gups", gups},
                             {"seconds",
                              {{"total", total},
                               {"preview", preview_seconds},
                               {"reading", t.reading},
                               {"filtering", t.filtering},
                               {"backprojection", t.backprojection},
                               {"transfer", t.transfer},
                               {"reconstruction", reconstruction},
                               {"writing", writing}}}};
    report["rows_filtered"] = fdk_totals.rows_filtered;
    report["memory"] = memory_json(*s, fdk_totals, reconstructor.device_names().size());
    if (written.structure == "bricked") report["memory"]["writer_layer_budget_bytes"] = import.layer_budget_bytes;
    if (mpi) report["seconds"]["building"] = building;
    if (import.keep) report["threshold"] = import.keep->threshold;
    if (mpi) report["ranks"] = ranks_json(ranks);
    if (s->json) {
      std::cout << report.dump(2) << "\n";
    } else if (!global.quiet) {
      std::cerr << std::fixed << std::setprecision(2) << "ivol recon: " << grid.size[0] << "x" << grid.size[1] << "x"
                << grid.size[2] << " voxels from " << scan.geometry.view_count() << " views on "
                << reconstructor.device_names().front() << " in " << total << " s (filtering " << t.filtering
                << " s, backprojection " << t.backprojection << " s = " << gups << " GUPS, writing " << writing << " s";
      if (mpi) std::cerr << ", building rank 0's slabs " << building << " s";
      std::cerr << "); " << s->output << ": " << human_bytes(written.file_bytes)
                << (written.structure == "bricked" ? ", a bricked grid" : ", an octree") << "\n";
      if (mpi) print_ranks(ranks);
    }
    return kExitOk;
  };
  return [run]() {
    if (!MpiRun::launched()) return run(nullptr);
    MpiRun mpi;
    try {
      return run(&mpi);
    } catch (const std::exception& e) {
      mpi.fail(e);  // ends every rank; rank 0's temporary file went as the error unwound
    }
  };
}

}  // namespace ivol::cli
