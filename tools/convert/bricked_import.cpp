#include "bricked_import.hpp"

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstring>
#include <thread>

#include "bricked_keep.hpp"
#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "ivol/geometry.hpp"
#include "ivol_source.hpp"
#include "sample_values.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

constexpr std::uint64_t kSixteenBitEncodingBytesPerVoxel = 32;

// What one encoding thread holds besides the layer: a brick several times
// over (its values, their byte planes or residuals and a candidate's, the
// compressed output's bound, zstd's tables, which grow with their input).
// A 16-bit brick's codec 3 holds more a voxel than a float32 brick's byte
// planes: the least-squares fit's values as doubles (8 bytes), the values,
// the best and the candidate's residuals, the entropy coder's tokens, bit
// lengths, contexts and output, codec 2's trial. Counted as 6 copies of a
// 16-bit brick, 128³ bricks held 7–23 MiB more than their --memory.
std::uint64_t brick_encoding_bytes(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding) {
  const std::uint64_t edge = std::uint64_t{1} << std::min(options.brick_log2, 31u);
  std::uint64_t voxels = 1;
  for (int a = 0; a < 3; ++a) voxels *= std::min<std::uint64_t>(edge, shape.dims[a]);
  return encoding == ValueEncoding::Float32 ? 6 * 4 * voxels : kSixteenBitEncodingBytesPerVoxel * voxels;
}

BrickedOptions bricked_options(const ImportOptions& options, const StreamingOptions& streaming, unsigned threads) {
  BrickedOptions bricked;
  bricked.threads = threads;
  bricked.brick_log2 = options.brick_log2;
  bricked.zstd_level = options.zstd_level;
  bricked.entropy = options.residual_coder;
  bricked.encoding = streaming.build.encoding;
  bricked.value_scale = streaming.build.value_scale;
  bricked.value_offset = streaming.build.value_offset;
  return bricked;
}

std::uint32_t layer_slices_of(const DenseVolume& shape, const ImportOptions& options) {
  return std::min<std::uint32_t>(shape.dims[2], 1u << std::min(options.brick_log2, 31u));
}

// Bytes per sample read: the sample, and a float32 copy where the samples
// are not float32 and not stored as they are (binary16 samples in a
// binary16 grid, integers as uint16 codes).
std::uint64_t read_bytes_per_voxel(const DenseVolume& shape, ValueEncoding encoding) {
  const bool codes = encoding == ValueEncoding::UInt16;
  const bool raw_binary16 = shape.type == SampleType::Float16 && encoding == ValueEncoding::Binary16;
  const bool float_copy = !codes && !raw_binary16 && shape.type != SampleType::Float32;
  return sample_size(shape.type) + (float_copy ? 4 : 0);
}

}  // namespace

std::uint64_t bricked_layer_bytes(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                                  std::uint32_t slices) {
  // 128-bit, so that no declared size overflows before it is compared.
  __extension__ using Wide = unsigned __int128;
  const Wide slice = Wide{shape.dims[0]} * shape.dims[1];
  const Wide layer = slice * layer_slices_of(shape, options);
  const unsigned width = encoding == ValueEncoding::Float32 ? 4 : 2;
  // The stored levels of detail (spec §8A.5, from level 3): per level a
  // slice of sums (8 bytes and a flag), a layer of its values (4 bytes
  // each) and their copy as the writer's values, and the 16-bit codes'
  // tables.
  Wide levels = 65536 * 17;
  for (unsigned k = 3; k <= depth_for(shape.dims); ++k) {
    const Dims level = lod_dims(shape.dims, k);
    levels +=
        Wide{level[0]} * level[1] *
        (9 + (4 + width) * std::min<std::uint64_t>(level[2], std::uint64_t{1} << std::min(options.brick_log2, 31u)));
  }
  // Whole layers read at once hold their stored values until they are added.
  const Wide stored = slice * std::max(slices, layer_slices_of(shape, options)) * width;
  // One encoding thread (the writer runs as many more as the budget holds:
  // encoder_threads) and a layer's blocks, held until written: --brick 128
  // held twice its --memory before they were counted.
  const Wide encoding_bytes = brick_encoding_bytes(shape, options, encoding) + layer * width;
  const Wide bytes =
      stored + layer * width + slice * slices * read_bytes_per_voxel(shape, encoding) + levels + encoding_bytes;
  return bytes > ~std::uint64_t{0} ? ~std::uint64_t{0} : static_cast<std::uint64_t>(bytes);
}

std::uint64_t bricked_layer_budget(const ImportOptions& options) {
  return options.layer_budget_bytes ? options.layer_budget_bytes : memory_budget(options.memory_bytes);
}

std::uint32_t bricked_read_slices(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                                  bool thick_reads_pay) {
  const std::uint64_t budget = bricked_layer_budget(options);
  const auto fits = [&](std::uint32_t slices) {
    return bricked_layer_bytes(shape, options, encoding, slices) <= budget;
  };
  const std::uint32_t layer = layer_slices_of(shape, options);
  if (!fits(1)) return 0;
  std::uint32_t slices = layer;
  if (fits(layer)) {
    // Whole layers, twice as many while they fit, up to the volume: a
    // reconstruction's slabs cost less per voxel the thicker they are.
    // Other sources read a layer at a time: a whole 512^3 volume read at
    // once cost a tenth more time, in page faults, than its layers read
    // into one buffer (bench/RESULTS.md, issue 22).
    if (!thick_reads_pay) return layer;
    const std::uint32_t all = static_cast<std::uint32_t>(
        std::min<std::uint64_t>((std::uint64_t{shape.dims[2]} + layer - 1) / layer * layer, UINT32_MAX / 2));
    while (slices < all && fits(std::min(2 * slices, all))) slices = std::min(2 * slices, all);
    return slices;
  }
  // Halving keeps the reads whole divisions of a layer of 2^b slices.
  while (slices > 1 && !fits(slices)) slices = (slices + 1) / 2;
  return slices;
}

unsigned encoder_threads(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding) {
  const std::uint64_t budget = bricked_layer_budget(options);
  const std::uint64_t held =
      bricked_layer_bytes(shape, options, encoding, std::max(1u, bricked_read_slices(shape, options, encoding)));
  const std::uint64_t spare = budget > held ? (budget - held) / brick_encoding_bytes(shape, options, encoding) : 0;
  return static_cast<unsigned>(std::min<std::uint64_t>(std::max(1u, std::thread::hardware_concurrency()), 1 + spare));
}

bool bricked_prefetch(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                      std::uint32_t read) {
  if (read == 0 || read > layer_slices_of(shape, options)) return false;
  __extension__ using Wide = unsigned __int128;
  const Wide slice = Wide{shape.dims[0]} * shape.dims[1];
  const Wide second = slice * layer_slices_of(shape, options) * (encoding == ValueEncoding::Float32 ? 4 : 2) +
                      slice * read * read_bytes_per_voxel(shape, encoding);
  const Wide held =
      Wide{bricked_layer_bytes(shape, options, encoding, read)} +
      Wide{encoder_threads(shape, options, encoding) - 1} * brick_encoding_bytes(shape, options, encoding);
  return held + second <= bricked_layer_budget(options);
}

bool choose_bricked(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                    ImportReport& report) {
  std::string against;
  // Under a keep rule an octree keeps an average a coarse leaf; a bricked
  // grid, when asked for, one background value outside (bricked_keep.hpp).
  if (options.keep && options.structure != StructureChoice::Bricked)
    against =
        "a keep rule coarsens regions, which only an octree holds as averages (--structure bricked stores "
        "one background value there instead)";
  if (!options.byte_planes) against = "--codec zstd (codec 1 only, for format 1.0/1.1 readers)";
  if (!options.framed_blocks) against = "format 1.2 (a bricked grid needs format 1.3)";
  if (options.structure == StructureChoice::Bricked) {
    if (!against.empty()) throw Error(ErrorClass::InvalidArgument, "--structure bricked: " + against);
    report.structure = "bricked";
    return true;
  }
  // An explicit choice records no reason (the command in the provenance
  // says it), so that a file asked for as an octree is the one ivol.write
  // and every other octree writer make from the same samples.
  if (options.structure == StructureChoice::Octree) {
    report.structure = "octree";
    return false;
  }
  if (against.empty() && options.input_coarse_leaves)
    against =
        "the .ivol input may hold coarse leaves (its metadata names a keep rule, a reconstruction into a structure "
        "or a loss): an octree keeps each as one leaf, a bricked grid would store every voxel of it "
        "(--structure bricked overrides)";
  if (against.empty() && bricked_read_slices(shape, options, encoding) == 0) {
    const std::uint64_t layer = bricked_layer_bytes(shape, options, encoding, 1);
    against = "a layer of bricks (" + mib_text(layer) +
              ") exceeds the memory budget (--memory), a slab of the octree writer does not";
    // Where the layer's budget is the whole of --memory (convert), say what
    // would write the smaller bricked grid.
    if (options.layer_budget_bytes == 0) against += "; " + memory_option_for(layer) + " writes a bricked grid";
    report.octree_for_memory = true;
  }
  if (!against.empty()) {
    report.structure = "octree";
    report.structure_reason = against;
    return false;
  }
  report.structure = "bricked";
  report.structure_reason =
      encoding == ValueEncoding::Float32
          ? "every voxel kept, as float32 values: bricks of their byte planes (codec 2, or 5 from --zstd-level 13) "
            "or, where noise dominates, their top bytes coded in context (codec 6) are smaller than an octree "
            "of one-voxel leaves, which stores averages and node words besides them (--structure octree overrides)"
          : "every voxel kept, as 16-bit values: bricks predicted in 3-D (codec 3), masked around their background "
            "(codec 4) or, where noise dominates, their top bytes coded in context (codec 6) are smaller than an "
            "octree of one-voxel leaves (--structure octree overrides)";
  return true;
}

bool stored_as_read(const DenseVolume& shape, const BuildOptions& build) {
  switch (build.encoding) {
    case ValueEncoding::Binary16:
      return shape.type == SampleType::Float16;
    case ValueEncoding::Float32:
      return shape.type == SampleType::Float32;
    case ValueEncoding::UInt16:
      return shape.type == SampleType::UInt16 && build.value_offset == 0.0;
  }
  return false;
}

void samples_to_stored(const DenseVolume& shape, const BuildOptions& build, const std::uint8_t* samples,
                       std::uint64_t count, std::vector<float>& scratch, std::uint16_t* stored, LossTally& loss) {
  if (build.encoding == ValueEncoding::UInt16) {
    to_codes(shape.type, samples, count, build.value_offset, stored);
    return;
  }
  if (shape.type == SampleType::Float16) {  // every bit as it is: -0 and NaN payloads included
    std::memcpy(stored, samples, count * 2);
    return;
  }
  const float* values = reinterpret_cast<const float*>(samples);
  if (shape.type != SampleType::Float32) {
    checked_resize(scratch, count, "a slab of samples as float32");
    to_float(shape, samples, count, scratch.data());
    values = scratch.data();
  }
  tally_encoding(build.encoding, values, count, loss);
  for (std::uint64_t i = 0; i < count; ++i) stored[i] = float_to_binary16_keep_nan(values[i]);
}

void samples_to_stored(const DenseVolume& shape, const BuildOptions& build, const std::uint8_t* samples,
                       std::uint64_t count, std::vector<float>& scratch, std::uint32_t* stored, LossTally& loss) {
  (void)loss;  // every sample type ivol reads is a float32 exactly: nothing to count
  if (build.encoding != ValueEncoding::Float32)
    throw Error(ErrorClass::InvalidArgument, "samples_to_stored: float32 bits asked for a 16-bit encoding");
  if (shape.type == SampleType::Float32) {  // every bit as it is: -0 and NaN payloads included
    std::memcpy(stored, samples, count * 4);
    return;
  }
  checked_resize(scratch, count, "a slab of samples as float32");
  to_float(shape, samples, count, scratch.data());
  std::memcpy(stored, scratch.data(), count * 4);
}

BrickedImport::BrickedImport(const DenseVolume& shape, const std::string& path, const ImportOptions& options,
                             const StreamingOptions& streaming)
    : shape_(shape),
      options_(options),
      path_(path),
      encoding_(streaming.build.encoding),
      layer_slices_(layer_slices_of(shape, options)),
      writer_(path, shape.dims, bricked_options(options, streaming, encoder_threads(shape, options, encoding_))) {
  // The metadata block is written last (the sources' digests and what
  // rounding lost are known only then): what is known now goes first, so
  // that a cut file keeps its voxel size, origin and unit (spec §15).
  Metadata early = options.metadata;
  if (shape.has_geometry) {
    early.voxel_size = shape.voxel_size;
    early.origin = shape.origin;
    early.unit = shape.unit;
  }
  early.structure["kind"] = "bricked";
  early.structure["brick"] = 1u << options.brick_log2;
  early.structure["source_encoding"] = sample_type_name(shape.type);
  inherit_structure(early, options.input_structure);
  writer_.write_early_metadata(early);
}

void BrickedImport::finish(const LossTally& loss, ImportReport& report, const BrickedKeepOutcome* keep) {
  report.encoding_loss = loss;
  refuse_encoding_loss(loss, shape_, options_, path_, encoding_);
  Metadata metadata = import_metadata(shape_, options_);
  report.lossless = loss.exact();
  report.max_abs_error = loss.max_error;
  if (keep) {
    report.threshold = keep->threshold;
    report.lossless = report.lossless && keep->max_abs_error == 0.0 && keep->nans_replaced == 0;
    report.max_abs_error = std::max(report.max_abs_error, keep->max_abs_error);
    nlohmann::json rule = {{"rule", "threshold"},
                           {"threshold", keep->threshold},
                           {"margin", options_.keep->margin},
                           {"outside", "background"},
                           {"background", keep->background},
                           {"background_rule", "the mean of the values below the threshold"},
                           {"kept_voxels", keep->kept},
                           {"background_voxels", keep->replaced}};
    if (options_.keep->otsu) rule["threshold_method"] = "otsu";
    if (keep->nans_replaced) rule["background_nans"] = keep->nans_replaced;
    metadata.structure["keep"] = std::move(rule);
  }
  metadata.structure["kind"] = "bricked";
  metadata.structure["brick"] = 1u << options_.brick_log2;
  metadata.structure["chosen_because"] = report.structure_reason;
  metadata.structure["source_encoding"] = sample_type_name(shape_.type);
  metadata.structure["lossless"] = report.lossless;
  metadata.structure["max_abs_error"] = report.max_abs_error;
  inherit_structure(metadata, options_.input_structure);
  report.file_bytes = writer_.finish(metadata).file_bytes;
  report.kept_voxels = keep ? keep->kept : shape_.voxel_count();
}

}  // namespace ivol::convert
