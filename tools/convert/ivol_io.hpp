// Dense volumes into and out of .ivol, slab by slab, through libformat's
// public API: memory holds one slab, never the whole volume.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "dense_volume.hpp"
#include "exactness.hpp"
#include "ivol/block_encoder.hpp"
#include "ivol/encoding.hpp"
#include "ivol/metadata.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/reader.hpp"
#include "ivol/streaming_writer.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

// Where full resolution is kept (the paper's rule): voxels above `threshold`
// (or above Otsu's threshold) grown by `margin` voxels; the rest is coarsened.
struct KeepRule {
  bool otsu = false;
  float threshold = 0.0f;
  unsigned margin = 0;
};
// Parses "threshold=T,margin=M" (T a number or "otsu"); throws InvalidArgument.
KeepRule parse_keep_rule(const std::string& text);

// Called with the slices done and the slices in all, a few times a second at most.
using Progress = std::function<void(std::uint64_t done, std::uint64_t total)>;

// How the file holds the voxels. Auto: a bricked regular grid (spec §8A.4:
// codec 3 for 16-bit values, codec 2 for float32) for every-voxel files,
// where it is smaller (an octree of one-voxel leaves also stores averages
// and node words, and its blocks cannot be predicted in 3-D:
// bench/RESULTS.md); an octree otherwise (a keep rule's coarse leaves, or
// format 1.2).
enum class StructureChoice { Auto, Octree, Bricked };

struct ImportOptions {
  StructureChoice structure = StructureChoice::Auto;
  unsigned brick_log2 = 5;                // bricked grid: bricks of 2^b voxels per side
  int zstd_level = 3;                     // of every block (readers do not care which)
  std::optional<ValueEncoding> encoding;  // default: lossless for the sample type
  std::optional<KeepRule> keep;           // default: lossless (equal leaves merge)
  std::uint32_t block_bytes = 0;          // 0: the library's default
  bool byte_planes = true;                // values over byte planes (codec 2, format 1.2)
  // How codec 3 codes residuals (PredictedOptions::Entropy): Auto (coder 3,
  // §7.2.2, at the default levels), Smaller (coder 2, §7.2.1, in bricks
  // under 64³), ZstdPlanes (zstd only), Lanes (coder 3 and no codec 6).
  PredictedOptions::Entropy residual_coder = PredictedOptions::Entropy::Auto;
  bool framed_blocks = true;              // format 1.3 framing (salvageable); false: format 1.2
  std::uint64_t slab_budget_bytes = 0;    // 0: the library's default
  std::uint64_t memory_bytes = 0;         // all the conversion may hold (--memory); 0: kDefaultMemoryBytes
  std::uint64_t layer_budget_bytes = 0;   // a bricked grid's layer (bricked_import.hpp); 0: memory_bytes
  std::shared_ptr<BlockEncoder> encoder;  // where blocks are compressed; null: here (ivol/block_encoder.hpp)
  std::string temp_directory;             // the octree writer's spill (--temp-dir); empty: TMPDIR, else the output's
  bool check_disk_space = true;           // refuse before any work when the disks lack room (disk_space.hpp)
  Metadata metadata;                      // provenance etc.; geometry from the volume
  // Called after the last slab, before the metadata is written: adds what was
  // computed meanwhile (the sources' digests, tools/cli/fixity.hpp).
  std::function<void(Metadata&)> complete_metadata;
  Progress progress;
  // False: when the encoding does not hold every sample bit for bit (e.g.
  // --encoding binary16 of float32 values), throw before the file is written
  // (ivol convert without --allow-lossy). The keep rule's coarsening is its
  // own request and is not counted.
  bool allow_lossy = true;
  std::string what;  // names the conversion in that refusal (default: the output path)
  // An .ivol input (ivol_source.hpp): the samples are its stored values, kept
  // as they are with its scale and offset (uint16 codes are not shifted by
  // the offset again); its structure object, of which inherit_structure
  // carries what still holds; and whether it may hold coarse leaves, which
  // StructureChoice::Auto then keeps in an octree.
  struct StoredValues {
    double scale = 1.0;
    double offset = 0.0;
  };
  std::optional<StoredValues> stored_values;
  nlohmann::json input_structure;
  bool input_coarse_leaves = false;
};

struct ImportReport {
  std::string structure = "octree";  // "octree" or "bricked"
  std::string structure_reason;      // why (the choice of StructureChoice::Auto, or the flag)
  bool octree_for_memory = false;    // Auto chose an octree only because a layer of bricks did not fit
  ValueEncoding encoding = ValueEncoding::Binary16;
  double value_scale = 1.0;
  double value_offset = 0.0;
  bool lossless = true;
  double max_abs_error = 0.0;
  LossTally encoding_loss;  // what the encoding's rounding changed (the keep rule's coarsening aside)
  float threshold = 0.0f;   // when a keep rule was applied
  std::uint64_t kept_voxels = 0;
  std::uint64_t file_bytes = 0;
  std::uint64_t slab_slices = 0;
  std::uint64_t temp_bytes = 0;  // peak temporary disk (the octree writer's spill file); 0 for a bricked grid
  std::string temp_directory;    // where it was
  double seconds = 0.0;
};

// The encoding that holds a sample type without loss: uint16 for u8/u16 (and
// i16 with an offset of -32768), binary16 for f16, float32 for f32.
ValueEncoding lossless_encoding(SampleType type);

ImportReport import_to_ivol(SlabReader& source, const std::string& path, const ImportOptions& options);

// import_to_ivol's steps, for a caller whose slabs are built elsewhere
// (recon_built_slabs.hpp), so that both write the same file. The writer's
// options for a volume of this shape (sets report's encoding, scale, offset).
StreamingOptions import_streaming_options(const DenseVolume& shape, const ImportOptions& options, ImportReport& report);
// Reads `source` `slab` slices at a time as float32 values, calling
// visit(values, count) for each slab; `what` names the reads in errors.
void for_each_float_slab(SlabReader& source, std::uint32_t slab, const std::string& what,
                         const std::function<void(const float*, std::uint64_t)>& visit);
// Otsu's threshold of a volume read `slab` slices at a time: one pass for
// the range, one for the histogram.
float streamed_otsu(SlabReader& source, std::uint32_t slab);
// The keep mask of slices [z0, z0 + count) from float samples of slices
// [lo, hi) of a volume `dims` (the slab and up to `margin` slices either side,
// which the mask's growth needs).
std::vector<std::uint8_t> slab_keep_mask(const float* values, const Dims& dims, std::uint32_t lo, std::uint32_t hi,
                                         std::uint32_t z0, std::uint32_t count, float threshold, unsigned margin);
// The offset integer samples are shifted by to become uint16 codes: the
// encoding's, except for an .ivol input's stored values (already codes).
double sample_code_offset(const ImportOptions& options, const BuildOptions& build);
// Unless options.allow_lossy: throws (refuse_loss) when `loss`, what storing
// the samples as `encoding` changed, is not exact.
void refuse_encoding_loss(const LossTally& loss, const DenseVolume& shape, const ImportOptions& options,
                          const std::string& path, ValueEncoding encoding);
// The file's metadata before the structure's entries: options.metadata,
// completed (complete_metadata), with the volume's geometry.
Metadata import_metadata(const DenseVolume& shape, const ImportOptions& options);
// After the last slab: the metadata (geometry, keep rule, outcome) and the
// file; fills report's outcome (lossless, error, kept voxels, bytes).
void finish_import(StreamingOctreeWriter& writer, const DenseVolume& shape, const ImportOptions& options,
                   ImportReport& report);
ImportReport import_to_ivol(const DenseVolume& volume, const std::string& path, const ImportOptions& options);

// The shape (dims, type, geometry; no samples) of a box of an .ivol file at a
// level of detail: voxel size scaled by 2^lod, origin at the box's first cell.
DenseVolume export_shape(const Reader& reader, const Box& box, unsigned lod, SampleType type);
// Called after the last slab, before the sink is finished: throws to refuse
// a conversion that was not exact (nothing is left at the output).
using LossCheck = std::function<void(const LossTally& loss, std::uint64_t voxels)>;

// Streams the box (full box when empty) to `sink`, created for
// export_shape(...): the stored values converted by stored_to_samples (bit
// for bit where the types agree, else exact or counted as loss: integers
// rounded and clamped). With `damaged`, reads past damaged blocks
// (Reader::read_box_bits's salvage) and lists the regions filled from coarser
// levels. Returns what the conversion changed. One slice (as float32 and
// as `type`) must fit in memory_bytes (--memory; 0: kDefaultMemoryBytes),
// and slabs take at most that, or 64 MiB.
LossTally export_from_ivol(Reader& reader, Box box, unsigned lod, SampleType type, SlabWriter& sink,
                           const Progress& progress = {}, std::vector<DamagedRegion>* damaged = nullptr,
                           const LossCheck& check = {}, std::uint64_t memory_bytes = 0);
// The same into memory.
DenseVolume export_from_ivol(Reader& reader, Box box, unsigned lod, SampleType type);
// The sample type that holds a file's values: the source's own type where the
// encoding, scale and offset give it back (structure.source_encoding u8 with
// uint16 codes -> u8; uint16 codes with integer scale and offset -> u16 or i16
// when their range fits; a binary16 file made from f16 -> f16), else f32,
// which holds every binary16 and float32 value and every uint16 value whose
// physical value is a float32 number.
SampleType natural_sample_type(const Reader& reader);
// The same among the float types, for OpenVDB: f16 for a binary16 file with
// scale 1 and offset 0 (a half-float grid holds it bit for bit), else f32.
SampleType natural_float_type(const Reader& reader);

}  // namespace ivol::convert
