// ivol convert IN OUT: between .ivol and raw, TIFF stacks, HDF5 and OpenVDB.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "fixity.hpp"
#include "formats.hpp"
#include "ivol/error.hpp"
#include "ivol/structures.hpp"
#include "ivol_io.hpp"
#include "ivol_source.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "report.hpp"
#include "salvage_report.hpp"
#include "signal_cleanup.hpp"
#include "sizes.hpp"
#include "volume_metadata.hpp"

namespace ivol::cli {
namespace {

struct ConvertSettings {
  std::string input, output, from, to;
  std::string dims, type = "f32", endian = "little", voxel_size, origin, unit;
  std::uint64_t header_bytes = 0;
  std::string dataset = "/exchange/data", grid;
  float background = 0.0f;
  std::string encoding, keep, quantity, value_unit;
  std::uint32_t block_bytes = 0;
  std::string codec = "zstd-planes";
  std::string entropy_coder = "auto";
  std::string format_version = "1.3";
  std::string structure = "auto";
  unsigned brick = 32;  // bricked grid: voxels per brick side
  int zstd_level = 3;
  std::uint64_t memory_mib = 0;
  std::string out_type;
  unsigned level = 0;
  bool force = false;
  bool allow_lossy = false;
  bool allow_gaps = false;
  bool salvage = false;
  std::string temp_dir;
  bool no_disk_check = false;
  bool json = false;
};

std::string describe(const convert::DenseVolume& v) {
  return std::string(convert::sample_type_name(v.type)) + " " + std::to_string(v.dims[0]) + "x" +
         std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]);
}

// The explicit options win over what the input says; the shape then carries
// the provenance the output is to have.
void settle_metadata(convert::DenseVolume& shape, const ConvertSettings& s, Format from, const std::string& command) {
  apply_geometry(shape, s.voxel_size, s.origin, s.unit);
  if (!s.quantity.empty()) shape.quantity = s.quantity;
  if (!s.value_unit.empty()) shape.value_unit = s.value_unit;
  if (!s.quantity.empty() || !s.value_unit.empty())
    shape.quantity_from = !s.quantity.empty() && !s.value_unit.empty() ? "--quantity, --value-unit"
                          : !s.quantity.empty()                        ? "--quantity"
                                                                       : "--value-unit";
  shape.provenance = convert::provenance_after_conversion(shape, command, s.input, format_name(from)).dump();
}

// Where geometry came from, after the summary line; an unknown voxel size
// is a warning (on stderr; --quiet prints nothing but errors, and the output
// records it anyway). A raw output keeps none of it: said too.
void print_geometry(const convert::DenseVolume& shape, const ConvertSettings& s, Format to, std::ostream& say,
                    bool quiet) {
  if (quiet) return;
  const bool raw = to == Format::Raw;
  if (!shape.has_geometry)
    std::cerr << "ivol convert: warning: " << s.input << " gives no voxel size and --voxel-size was not given"
              << (raw ? "\n" : "; the output records it as unknown (provenance voxel_size_known = false)\n");
  for (const std::string& line : convert::geometry_summary(shape)) say << "  " << line << "\n";
  if (raw) say << "  (a raw file keeps no geometry or metadata: note them down)\n";
}

// Slices larger than the memory budget, a band of rows at a time (each
// within the budget, at most 64 MiB): source and sink both work by rows.
void convert_in_bands(convert::SlabReader& source, const convert::DenseVolume& shape, const std::string& output,
                      Format to, ForeignOptions foreign, std::uint64_t budget, bool quiet) {
  const std::uint64_t row = convert::slab_bytes(Dims{shape.dims[0], 1, 1}, 1, shape.type, output);
  convert::require_within_budget(row, budget, output + ": one row of " + describe(shape));
  auto band = static_cast<std::uint32_t>(
      std::clamp<std::uint64_t>(std::min<std::uint64_t>(64ull << 20, budget) / row, 1, shape.dims[1]));
  // Whole multiples of 64 rows, the height of the HDF5 writer's chunks.
  if (band > 64) band -= band % 64;
  foreign.band_rows = band;
  std::vector<std::uint8_t> buffer;
  convert::checked_resize(buffer, std::uint64_t{band} * row, output + ": a band of " + std::to_string(band) + " rows");
  const auto sink = create_sink(output, to, shape, foreign);
  if (!sink->writes_rows()) throw Error(ErrorClass::LimitExceeded, output + ": this output cannot be written by rows");
  const auto progress = progress_bar("ivol convert", quiet);
  for (std::uint32_t z = 0; z < shape.dims[2]; ++z) {
    for (std::uint64_t y = 0; y < shape.dims[1]; y += band) {  // 64-bit: a height near 2^32 must not wrap
      const auto n = static_cast<std::uint32_t>(std::min<std::uint64_t>(band, shape.dims[1] - y));
      source.read_rows(z, static_cast<std::uint32_t>(y), n, buffer.data());
      sink->write_rows(buffer.data(), n);
    }
    if (progress) progress(z + 1, shape.dims[2]);
  }
  sink->finish();
}

}  // namespace

Runner add_convert_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("convert",
                                 "Convert between .ivol and raw, TIFF stacks, HDF5 and OpenVDB; .ivol to .ivol "
                                 "re-encodes an archive (every stored value kept)");
  auto s = std::make_shared<ConvertSettings>();
  cmd->add_option("IN", s->input, "Input file (or folder of TIFF slices); - : raw samples on standard input")
      ->required();
  cmd->add_option("OUT", s->output, "Output file; - : raw samples on standard output")->required();
  cmd->add_option("--from", s->from, "Input format: ivol, raw, tiff, hdf5, vdb (default: by extension)");
  cmd->add_option("--to", s->to, "Output format (default: by extension)");
  cmd->add_flag("-f,--force", s->force, "Replace OUT if it exists");
  cmd->add_flag("--allow-lossy", s->allow_lossy,
                "Convert even where the output does not hold every value exactly (the summary reports the loss)");
  auto* raw = cmd->add_option_group("raw input");
  raw->add_option("--dims", s->dims, "X,Y,Z voxels")->check(checked([](const std::string& v) {
    parse_dims(v, "--dims");
  }));
  raw->add_option("--type", s->type, "Sample type of a raw input: u8, u16, i16, f16, f32")
      ->check(checked([](const std::string& v) { parse_sample_type(v, "--type"); }))
      ->capture_default_str();
  raw->add_option("--endian", s->endian, "little or big")
      ->check(CLI::IsMember({"little", "big"}))
      ->capture_default_str();
  raw->add_option("--header-bytes", s->header_bytes, "Bytes to skip before the first sample")->check(whole_number());
  auto* geometry = cmd->add_option_group("geometry");
  geometry->add_option("--voxel-size", s->voxel_size, "S or SX,SY,SZ (overrides the input's)")
      ->check(checked([](const std::string& v) {
        convert::DenseVolume probe;
        apply_geometry(probe, v, "", "");
      }));
  geometry->add_option("--origin", s->origin, "X,Y,Z of the centre of voxel 0")
      ->check(checked([](const std::string& v) { parse_triple(v, "--origin", false); }));
  geometry->add_option("--unit", s->unit, "Length unit, e.g. mm");
  cmd->add_flag("--allow-gaps", s->allow_gaps, "TIFF folder: convert although slice numbers are missing");
  cmd->add_flag("--salvage", s->salvage,
                ".ivol to .ivol: read past damaged blocks and (format 1.3) a cut or damaged index, filling their "
                "regions from the nearest readable coarser level; the regions are listed, recorded in "
                "provenance.salvage, the file marked not lossless, and the exit code is 3");
  cmd->add_option("--dataset", s->dataset, "HDF5 dataset")->capture_default_str();
  cmd->add_option("--grid", s->grid, "OpenVDB grid (default: the first float grid)");
  cmd->add_option("--background", s->background, "OpenVDB output: background value")->check(number_in(-3.4e38, 3.4e38));
  auto* into = cmd->add_option_group("into .ivol");
  into->add_option("--encoding", s->encoding, "binary16, uint16 or float32 (default: lossless for the input)")
      ->check(CLI::IsMember({"binary16", "uint16", "float32"}));
  into->add_option("--keep", s->keep, "threshold=T|otsu,margin=M: full resolution only around the object")
      ->check(checked([](const std::string& v) { parse_keep(v, "--keep"); }));
  into->add_option("--block-size", s->block_bytes, "Decoded bytes per block")->check(whole_number());
  into->add_option("--codec", s->codec,
                   "zstd-planes: values over byte planes (format 1.2, smaller); zstd: format 1.0/1.1 readers read it")
      ->check(CLI::IsMember({"zstd-planes", "zstd"}))
      ->capture_default_str();
  into->add_option(
          "--entropy-coder", s->entropy_coder,
          "Bricked grid: how a predicted brick's residuals are coded (codec 3). auto: at --zstd-level 3 and "
          "below, the tokens under stored tables with 32 rANS states (spec 7.2.2; predicted bricks decode at "
          "about 430 MB/s a core in 32^3 bricks, 530 in 64^3, with AVX2), above that as smaller; zstd over byte "
          "planes where a brick is nearly flat or small and that is smaller, and codec 6 where noise dominates "
          "(about 120 MB/s); smaller: rANS over tokens with adaptive contexts in bricks under 64^3 (spec 7.2.1: "
          "files 0.3-0.5 % smaller in 32^3 bricks, decoding at about 240 MB/s); zstd: byte planes only (about "
          "500 MB/s, files 1-6 % larger), no codec 6; lanes: stored tables and 32 states in every brick, no "
          "codec 6")
      ->check(CLI::IsMember({"auto", "smaller", "zstd", "lanes"}))
      ->capture_default_str();
  into->add_option("--format-version", s->format_version,
                   "1.3: framed blocks, salvageable when cut; 1.2: for readers older than 1.3 (with --codec zstd, "
                   "for 1.0/1.1 readers)")
      ->check(CLI::IsMember({"1.3", "1.2"}))
      ->capture_default_str();
  into->add_option("--structure", s->structure,
                   "auto: a bricked regular grid for every voxel kept (16-bit values: bricks predicted in 3-D, "
                   "codec 3; float32: bricks of byte planes, codec 2; either: the top byte in context, codec 6, where "
                   "noise dominates), else an octree; octree or bricked to choose (with --keep, bricked stores one "
                   "background value outside the kept region, the mean of the values below the threshold, where an "
                   "octree keeps an average a coarse leaf: a smaller file)")
      ->check(CLI::IsMember({"auto", "octree", "bricked"}))
      ->capture_default_str();
  CLI::Option* brick_option =
      into->add_option(
              "--brick", s->brick,
              "Bricked grid: voxels per brick side, 4 to 128, a power of two (32: smallest file; 16: a slice "
              "reads about half the bytes, the file at 512^3 1.6 % larger with every voxel kept, 6-7 % at object "
              "fidelity)")
          ->check(CLI::IsMember({4u, 8u, 16u, 32u, 64u, 128u}))
          ->capture_default_str();
  into->add_option("--zstd-level", s->zstd_level,
                   "zstd level of every block, 1 to 19: higher is smaller and slower to write, never slower to read "
                   "(19: 0.5 % smaller for a bricked grid of 16-bit values, 2 % for one of float32, 3 % for an "
                   "octree, at a fifth to a twentieth of the speed; from 13 on, blocks of byte planes are a zstd "
                   "frame a plane, codec 5); a bricked grid's predicted bricks (codec 3) use level 1 up to level 3, "
                   "where it is as small and twice as fast")
      ->check(CLI::Range(1, 19))
      ->capture_default_str();
  into->add_option("--memory", s->memory_mib, "About how many MiB the conversion may hold (default 2048)")
      ->check(mebibytes());
  into->add_option("--temp-dir", s->temp_dir,
                   "Directory of the octree writer's temporary spill file (default: $TMPDIR, else OUT's directory)");
  into->add_flag("--no-disk-check", s->no_disk_check,
                 "Skip the check that OUT's and the spill file's disks have the room the run is estimated to need");
  into->add_flag("--json", s->json, "Print the outcome as JSON on stdout (sizes, peak temporary disk)");
  into->add_option("--quantity", s->quantity, "What the values are, e.g. linear_attenuation");
  into->add_option("--value-unit", s->value_unit, "Unit of the values, e.g. 1/mm");
  auto* out_of = cmd->add_option_group("out of .ivol");
  out_of
      ->add_option("--out-type", s->out_type,
                   "u8, u16, i16, f16, f32 (default: the type that holds the file's values; OpenVDB: f32, or f16 "
                   "for binary16 files)")
      ->check(checked([](const std::string& v) { parse_sample_type(v, "--out-type"); }));
  out_of->add_option("--level", s->level, "Level of detail: 1/2^K resolution")->check(whole_number());

  return [s, &global, brick_option]() {
    const auto start = std::chrono::steady_clock::now();
    const Format from = detect_format(s->input, s->from, "--from");
    const Format to = output_format(s->output, s->to, "OUT");
    remove_temporaries_on_signal(s->output);
    if (s->salvage && !(from == Format::Ivol && to == Format::Ivol))
      throw UsageError("--salvage", "salvages .ivol into .ivol (ivol extract --salvage writes other formats)");
    if (from == Format::Ivol && to == Format::Ivol) {
      // A re-encoding keeps every voxel; a level of detail or another sample
      // type belongs to an export.
      if (s->level != 0)
        throw UsageError("--level",
                         "ivol to ivol re-encodes the full resolution; extract a level to raw, TIFF or HDF5");
      if (!s->out_type.empty())
        throw UsageError("--out-type", "ivol to ivol keeps the stored values (--encoding changes their encoding)");
    }
    if (is_stdio(s->input) && from != Format::Raw) throw UsageError("IN", "'-' (standard input) takes raw input only");
    check_output(s->output, "OUT", {s->input}, s->force, /*stdout_allowed=*/true);
    // The summary must not mix with samples on standard output.
    std::ostream& say = is_stdio(s->output) ? std::cerr : std::cout;

    ForeignOptions foreign;
    foreign.dataset = s->dataset;
    foreign.grid = s->grid;
    foreign.background = s->background;
    foreign.big_endian = s->endian == "big";
    foreign.memory_bytes = convert::checked_mul(s->memory_mib, std::uint64_t{1} << 20, "--memory");
    foreign.allow_lossy = s->allow_lossy;
    if (!s->dims.empty()) {
      foreign.raw.dims = parse_dims(s->dims, "--dims");
      foreign.raw_dims_given = true;
    }
    foreign.raw.type = parse_sample_type(s->type, "--type");
    foreign.raw.big_endian = s->endian == "big";
    foreign.raw.header_bytes = s->header_bytes;
    foreign.allow_gaps = s->allow_gaps;

    if (to == Format::Ivol) {
      // Options that cannot hold together are a bad command line (exit 1),
      // refused before any work.
      if (s->structure == "bricked") {
        if (s->codec == "zstd")
          throw UsageError("--structure", "bricked: --codec zstd (codec 1 only, for format 1.0/1.1 readers)");
        if (s->format_version == "1.2")
          throw UsageError("--structure", "bricked: format 1.2 (a bricked grid needs format 1.3)");
      }
      if (brick_option->count() > 0) {
        if (s->structure == "octree")
          throw UsageError("--brick", "bricks belong to a bricked grid, and --structure octree asks for an octree");
        if (s->format_version == "1.2")
          throw UsageError("--brick", "bricks belong to a bricked grid, which format 1.2 (--format-version) lacks");
      }
      bool rounded = false;  // by the reader (HDF5 float64), already said
      convert::IvolSourceInfo ivol_input;
      convert::IvolStoredSlabs* ivol_source = nullptr;
      std::unique_ptr<convert::SlabReader> opened;
      if (from == Format::Ivol) {
        auto input = convert::open_ivol_stored_slabs(s->input, foreign.memory_bytes, &ivol_input, s->salvage);
        ivol_source = input.get();
        if (input->salvage() && !global.quiet) {
          std::cerr << "ivol convert: " << input->salvage()->reason << "\n";
          print_salvage(std::cerr, "  ", *input->salvage(), input->layout());
        }
        opened = std::move(input);
      } else {
        opened = open_source(s->input, from, foreign, &rounded);
      }
      convert::DenseVolume shape = convert::shape_of(opened->shape());
      settle_metadata(shape, *s, from, global.command_line);
      // finish_import takes the geometry from the source's shape: give it ours.
      const auto source = convert::reshaped_slabs(std::move(opened), shape);
      convert::ImportOptions options;
      if (!s->encoding.empty()) options.encoding = parse_encoding(s->encoding);
      if (!s->keep.empty()) options.keep = parse_keep(s->keep, "--keep");
      options.block_bytes = s->block_bytes;
      options.brick_log2 = 0;  // --brick is a power of two, checked above
      while ((1u << options.brick_log2) < s->brick) ++options.brick_log2;
      options.zstd_level = s->zstd_level;
      options.byte_planes = s->codec == "zstd-planes";
      options.residual_coder = s->entropy_coder == "zstd"      ? ivol::PredictedOptions::Entropy::ZstdPlanes
                               : s->entropy_coder == "lanes"   ? ivol::PredictedOptions::Entropy::Lanes
                               : s->entropy_coder == "smaller" ? ivol::PredictedOptions::Entropy::Smaller
                                                               : ivol::PredictedOptions::Entropy::Auto;
      options.framed_blocks = s->format_version == "1.3";
      options.structure = s->structure == "octree"    ? convert::StructureChoice::Octree
                          : s->structure == "bricked" ? convert::StructureChoice::Bricked
                                                      : convert::StructureChoice::Auto;
      // A slab's samples are held about four times over (as read, as float,
      // the keep mask, the subtrees being built): give a quarter to the slab.
      options.slab_budget_bytes = foreign.memory_bytes / 4;
      options.memory_bytes = foreign.memory_bytes;
      options.metadata.provenance = nlohmann::json::parse(shape.provenance);
      if (from == Format::Ivol) convert::set_reencoding(options, ivol_input);
      // Hashed on a thread of its own while the conversion reads the same files.
      // With what reads the source again (ivol verify --against).
      nlohmann::json how = {{"format", format_name(from)}, {"sample_type", convert::sample_type_name(shape.type)}};
      if (from == Format::Raw) how.update({{"endian", s->endian}, {"header_bytes", s->header_bytes}});
      if (from == Format::Hdf5) how["dataset"] = s->dataset;
      if (from == Format::Vdb && !s->grid.empty()) how["grid"] = s->grid;
      if (from == Format::Ivol && is_remote_path(s->input)) {
        // Read by byte ranges, never downloaded whole: hashing it would fetch
        // every byte again. Recorded by its address and size.
        nlohmann::json entry = how;
        entry.update({{"path", s->input},
                      {"bytes", ivol_input.file_bytes},
                      {"sha256_omitted", "read over HTTP by byte ranges, not downloaded whole"}});
        options.complete_metadata = [entry](Metadata& m) { m.provenance["sources"] = nlohmann::json::array({entry}); };
      } else {
        auto digests =
            std::make_shared<SourceDigests>(std::vector<std::string>{s->input}, std::vector<nlohmann::json>{how});
        options.complete_metadata = SourceDigests::filler(digests);
      }
      if (ivol_source)  // read past damage: say what was filled (the reads are done when this runs)
        options.complete_metadata = [fill = options.complete_metadata, ivol_source](Metadata& m) {
          fill(m);
          if (ivol_source->lost_something()) m.provenance["salvage"] = convert::salvage_record(*ivol_source);
        };
      if (!shape.quantity.empty()) options.metadata.quantity = shape.quantity;
      options.metadata.value_unit = shape.value_unit;
      if (shape.has_geometry) {
        options.metadata.voxel_size = shape.voxel_size;
        options.metadata.origin = shape.origin;
        options.metadata.unit = shape.unit;
      } else {  // an .ivol file needs a voxel size: one pixel, marked unknown
        options.metadata.voxel_size = {1.0, 1.0, 1.0};
        options.metadata.origin = {0.0, 0.0, 0.0};
        options.metadata.unit = "pixel";
      }
      options.progress = progress_bar("ivol convert", global.quiet || s->json);
      options.allow_lossy = s->allow_lossy;
      options.what = s->input + " -> " + s->output;
      options.temp_directory = s->temp_dir;
      options.check_disk_space = !s->no_disk_check;
      const convert::ImportReport r = convert::import_to_ivol(*source, s->output, options);
      const int done = ivol_source && ivol_source->lost_something() ? kExitSalvaged : kExitOk;
      if (done == kExitSalvaged && ivol_source->salvage() && ivol_source->salvage()->metadata == "early")
        std::cerr << "ivol convert: salvaged without the input's full metadata (" << ivol_source->salvage()->metadata
                  << "; recorded in provenance.salvage): keys it held may be missing from the output\n";
      if (done == kExitSalvaged && !ivol_source->metadata_problem().empty())
        std::cerr << "ivol convert: salvaged without the input's metadata, which cannot be read ("
                  << ivol_source->metadata_problem() << "; recorded in provenance.salvage)\n";
      if (done == kExitSalvaged && ivol_source->damaged_count() > 0) {
        const auto& damaged = ivol_source->damaged();
        std::cerr << "ivol convert: salvaged " << ivol_source->damaged_count()
                  << " region(s) from coarser levels because blocks are damaged or missing (recorded in "
                     "provenance.salvage; the file is marked not lossless):\n";
        for (std::size_t n = 0; n < damaged.size() && n < 10; ++n)
          std::cerr << "  " << damaged[n].region.to_string() << " (level " << damaged[n].level
                    << "): " << damaged[n].message << "\n";
        if (ivol_source->damaged_count() > 10)
          std::cerr << "  ... and " << ivol_source->damaged_count() - 10 << " more\n";
      }
      if (s->json) {
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        nlohmann::json report = {{"output", s->output},
                                 {"structure", r.structure},
                                 {"encoding", encoding_name(r.encoding)},
                                 {"lossless", r.lossless && !rounded},
                                 {"max_abs_error", r.max_abs_error},
                                 {"input_bytes", convert::slab_bytes(shape.dims, shape.dims[2], shape.type, s->input)},
                                 {"file_bytes", r.file_bytes},
                                 {"temp_bytes", r.temp_bytes},
                                 {"seconds", seconds}};
        if (!r.temp_directory.empty()) report["temp_directory"] = r.temp_directory;
        if (from == Format::Ivol) report["input_file_bytes"] = ivol_input.file_bytes;
        std::cout << report.dump(2) << "\n";
        return done;
      }
      if (global.verbose)
        std::cerr << "ivol convert: " << encoding_name(r.encoding) << " (physical = " << r.value_offset << " + "
                  << r.value_scale << " x stored), slabs of " << r.slab_slices << " slices, "
                  << (options.keep ? "threshold " + std::to_string(r.threshold) + ", " : std::string()) << r.kept_voxels
                  << " voxels at full resolution\n";
      if (!global.quiet) {
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const std::uint64_t bytes = convert::slab_bytes(shape.dims, shape.dims[2], shape.type, s->input);
        if (!r.lossless) {
          std::string steps;
          if (!r.encoding_loss.exact())
            steps = std::string(convert::sample_type_name(shape.type)) + " rounded to " + encoding_name(r.encoding) +
                    " in " + std::to_string(r.encoding_loss.voxels) + " of " + std::to_string(shape.voxel_count()) +
                    " voxels";
          if (options.keep)
            steps += std::string(steps.empty() ? "" : ", ") + "coarsened outside the kept region (threshold " +
                     std::to_string(r.threshold) + ")";
          std::cerr << "ivol convert: lossy: " << steps << "; largest error " << r.max_abs_error << "\n";
        }
        // A bricked grid is far smaller for such input: say why it is not one.
        if (r.octree_for_memory) std::cerr << "ivol convert: note: an octree, because " << r.structure_reason << "\n";
        if (from == Format::Ivol) {
          // A re-encoding: the sizes of the two files, not of the samples.
          const double change = 100.0 * (static_cast<double>(r.file_bytes) / ivol_input.file_bytes - 1.0);
          std::ostringstream percent;
          percent.precision(1);
          percent << std::fixed << std::abs(change) << " % " << (change <= 0 ? "smaller" : "larger");
          say << s->input << " (ivol " << structure_name(ivol_input.kind) << " " << encoding_name(ivol_input.encoding)
              << ", " << human_bytes(ivol_input.file_bytes) << ") -> " << s->output << " (ivol " << r.structure << " "
              << encoding_name(r.encoding) << ", " << human_bytes(r.file_bytes) << ", " << percent.str()
              << (done == kExitSalvaged ? ", salvaged: see provenance.salvage"
                  : r.lossless          ? ", every stored value as it was"
                                        : "")
              << ") in " << seconds << " s\n";
          print_geometry(shape, *s, to, say, global.quiet);
          return done;
        }
        say << s->input << " (" << format_name(from) << " " << describe(shape) << ", " << human_bytes(bytes) << ") -> "
            << s->output << " (ivol " << r.structure << " " << encoding_name(r.encoding) << ", "
            << human_bytes(r.file_bytes) << ", " << static_cast<double>(bytes) / r.file_bytes << "x smaller"
            << (r.lossless && !rounded ? ", lossless" : "") << ") in " << seconds << " s\n";
      }
      print_geometry(shape, *s, to, say, global.quiet);
      return done;
    }

    if (from != Format::Ivol) {
      const auto source = open_source(s->input, from, foreign);
      convert::DenseVolume shape = convert::shape_of(source->shape());
      settle_metadata(shape, *s, from, global.command_line);
      // Sized before the output exists: a refusal leaves nothing behind.
      const std::uint64_t slice = convert::slab_bytes(shape.dims, 1, shape.type, s->input);
      const std::uint64_t budget = convert::memory_budget(foreign.memory_bytes);
      // A slice beyond the budget goes a band of rows at a time where both
      // ends can: raw, TIFF, MetaImage and NRRD input; raw (a file or
      // standard output), TIFF, HDF5, MetaImage and NRRD output.
      if (slice > budget && source->reads_rows() && writes_rows(to)) {
        convert_in_bands(*source, shape, s->output, to, foreign, budget, global.quiet);
        if (!global.quiet) say << s->input << " -> " << s->output << " (" << describe(shape) << ", in bands of rows)\n";
        print_geometry(shape, *s, to, say, global.quiet);
        return kExitOk;
      }
      convert::require_within_budget(slice, budget, s->input + ": one slice of " + describe(shape));
      // An OpenVDB output holds the whole volume and its tree within the
      // budget (its sink weighs them with one slice read): larger slabs
      // would buy nothing but memory beyond it.
      const auto slab = to == Format::Vdb
                            ? 1u
                            : static_cast<std::uint32_t>(std::clamp<std::uint64_t>(
                                  std::min<std::uint64_t>(64ull << 20, budget) / slice, 1, shape.dims[2]));
      std::vector<std::uint8_t> buffer;
      convert::checked_resize(buffer, std::uint64_t{slab} * slice,
                              s->input + ": a slab of " + std::to_string(slab) + " slices");
      const auto sink = create_sink(s->output, to, shape, foreign);
      const auto progress = progress_bar("ivol convert", global.quiet);
      for (std::uint32_t z = 0; z < shape.dims[2]; z += slab) {
        const std::uint32_t n = std::min(slab, shape.dims[2] - z);
        source->read(z, n, buffer.data());
        sink->write(buffer.data(), n);
        if (progress) progress(z + n, shape.dims[2]);
      }
      sink->finish();
      if (!global.quiet) say << s->input << " -> " << s->output << " (" << describe(shape) << ")\n";
      print_geometry(shape, *s, to, say, global.quiet);
      return kExitOk;
    }

    ReaderOptions reader_options;
    reader_options.cache_bytes = convert::export_cache_bytes(foreign.memory_bytes);
    Reader reader(s->input, reader_options);
    warn_if_fetched_whole(reader, "ivol convert");
    const convert::SampleType natural = natural_export_type(to, reader);
    const convert::SampleType type = s->out_type.empty() ? natural : parse_sample_type(s->out_type, "--out-type");
    check_export_type(to, type, "--out-type");
    require_level_within(s->level, reader);
    const Box box = full_box(reader.layout().dims, s->level);
    convert::DenseVolume shape = convert::export_shape(reader, box, s->level, type);
    settle_metadata(shape, *s, from, global.command_line);
    const std::string what = s->input + " -> " + s->output + " as " + convert::sample_type_name(type);
    const convert::LossCheck check = exactness_check(s->allow_lossy, what, type, natural, "--out-type");
    check_before_streaming(s->output, reader, box, s->level, type, check, false);
    const auto sink = create_sink(s->output, to, shape, foreign);
    const convert::LossTally loss =
        convert::export_from_ivol(reader, box, s->level, type, *sink, progress_bar("ivol convert", global.quiet),
                                  nullptr, check, foreign.memory_bytes);
    if (!loss.exact() && !global.quiet)
      std::cerr << "ivol convert: lossy: " << what << ": "
                << convert::describe_loss(loss, shape.voxel_count(), convert::sample_type_name(type)) << "\n";
    if (!global.quiet)
      say << s->input << " -> " << s->output << " (" << format_name(to) << " " << describe(shape)
          << (s->level ? ", level of detail " + std::to_string(s->level) : std::string())
          << (loss.exact() ? "" : ", lossy") << ")\n";
    print_geometry(shape, *s, to, say, global.quiet);
    return kExitOk;
  };
}

}  // namespace ivol::cli
