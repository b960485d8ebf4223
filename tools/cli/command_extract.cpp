// ivol extract FILE --box ... -o OUT: a region, at full resolution or at a
// level of detail, as raw or TIFF (or HDF5/OpenVDB).
#include <filesystem>
#include <iostream>

#include "commands.hpp"
#include "formats.hpp"
#include "ivol/error.hpp"
#include "ivol_io.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "report.hpp"
#include "salvage_report.hpp"
#include "signal_cleanup.hpp"

namespace ivol::cli {
namespace {

// How much of the file the extraction read. The reader counts every byte it
// read, the index and blocks read twice included, so the count can pass the
// file's size: then say so rather than print "550 of 534 bytes".
std::string reader_share(const Reader& reader) {
  const std::uint64_t read = reader.io_stats().bytes_read, size = reader.info().file_size;
  if (read <= size) return "read " + std::to_string(read) + " of " + std::to_string(size) + " bytes";
  return "read " + std::to_string(read) + " bytes, some more than once, from a " + std::to_string(size) + "-byte file";
}

}  // namespace

Runner add_extract_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("extract", "Write a region of an .ivol file as raw, TIFF, HDF5 or OpenVDB");
  struct Settings {
    std::string file, box, output, to, type, endian = "little";
    unsigned level = 0;
    bool force = false;
    bool salvage = false;
    bool allow_lossy = false;
  };
  auto s = std::make_shared<Settings>();
  cmd->add_option("FILE", s->file, "The .ivol file")->required();
  cmd->add_option("--box", s->box, "x0,y0,z0,x1,y1,z1 (half-open, in voxels of the chosen level)")
      ->required()
      ->check(checked([](const std::string& v) { parse_box(v, "--box"); }));
  cmd->add_option("--level", s->level, "Level of detail: 1/2^K resolution")->check(whole_number());
  cmd->add_option("-o,--output", s->output, "Output file: .raw, .tif, .h5, .vdb; - : raw samples on standard output")
      ->required();
  cmd->add_option("--to", s->to, "Output format (default: by extension)");
  cmd->add_option("--type", s->type,
                  "u8, u16, i16, f16, f32 (default: the type that holds the file's values; OpenVDB: f32, or f16 for "
                  "binary16 files)")
      ->check(checked([](const std::string& v) { parse_sample_type(v, "--type"); }));
  cmd->add_flag("--allow-lossy", s->allow_lossy,
                "Write even where the type does not hold every value exactly (the summary reports the loss)");
  cmd->add_option("--endian", s->endian, "Raw output byte order")->check(CLI::IsMember({"little", "big"}));
  cmd->add_flag("-f,--force", s->force, "Replace the output if it exists");
  cmd->add_flag("--salvage", s->salvage,
                "Read past damaged blocks and a cut or damaged index (format 1.3 files): missing regions take the "
                "average of a coarser level (exit 3)");
  return [s, &global]() {
    const Format to = output_format(s->output, s->to, "-o");
    if (to == Format::Ivol) throw UsageError("-o", "extract writes dense formats, not .ivol");
    check_output(s->output, "-o", {s->file}, s->force, /*stdout_allowed=*/true);
    remove_temporaries_on_signal(s->output);
    std::ostream& say = is_stdio(s->output) ? std::cerr : std::cout;  // not among the samples
    ReaderOptions reader_options;
    reader_options.salvage = s->salvage;
    Reader reader(s->file, reader_options);
    warn_if_fetched_whole(reader, "ivol extract");
    if (reader.info().salvage) {
      std::cerr << "ivol extract: " << reader.info().salvage->reason << "\n";
      print_salvage(std::cerr, "  ", *reader.info().salvage, reader.layout());
    }
    if (!reader.metadata_problem().empty())
      std::cerr << "ivol extract: the metadata cannot be read (" << reader.metadata_problem()
                << "): the output gets no voxel size, origin or quantity from it\n";
    const convert::SampleType natural = natural_export_type(to, reader);
    const convert::SampleType type = s->type.empty() ? natural : parse_sample_type(s->type, "--type");
    check_export_type(to, type, "--type");
    const Box box = parse_box(s->box, "--box");
    require_level_within(s->level, reader);
    ForeignOptions options;
    options.big_endian = s->endian == "big";
    options.allow_lossy = s->allow_lossy;
    const convert::DenseVolume shape = convert::export_shape(reader, box, s->level, type);
    // Refuse a bad box before creating the output.
    const Dims limit = lod_dims(reader.layout().dims, s->level);
    for (int a = 0; a < 3; ++a)
      if (box.lo[a] >= box.hi[a] || box.hi[a] > limit[a])
        throw UsageError("--box", box.to_string() + " is empty or outside the volume (" + std::to_string(limit[0]) +
                                      "x" + std::to_string(limit[1]) + "x" + std::to_string(limit[2]) + " at level " +
                                      std::to_string(s->level) + ")");
    const std::string what = s->file + " -> " + s->output + " as " + convert::sample_type_name(type);
    const convert::LossCheck check = exactness_check(s->allow_lossy, what, type, natural, "--type");
    check_before_streaming(s->output, reader, box, s->level, type, check, s->salvage);
    const auto sink = create_sink(s->output, to, shape, options);
    std::vector<DamagedRegion> damaged;
    const convert::LossTally loss =
        convert::export_from_ivol(reader, box, s->level, type, *sink, {}, s->salvage ? &damaged : nullptr, check);
    if (!loss.exact() && !global.quiet)
      std::cerr << "ivol extract: lossy: " << what << ": "
                << convert::describe_loss(loss, shape.voxel_count(), convert::sample_type_name(type)) << "\n";
    if (!damaged.empty()) {
      std::cerr << "ivol extract: salvaged " << damaged.size()
                << " region(s) from coarser levels because blocks are damaged or missing:\n";
      for (std::size_t n = 0; n < damaged.size() && n < 10; ++n)
        std::cerr << "  " << damaged[n].region.to_string() << " (level " << damaged[n].level
                  << "): " << damaged[n].message << "\n";
      if (damaged.size() > 10) std::cerr << "  ... and " << damaged.size() - 10 << " more\n";
    }
    if (!global.quiet)
      say << s->output << ": " << convert::sample_type_name(type) << " " << shape.dims[0] << "x" << shape.dims[1] << "x"
          << shape.dims[2] << " from " << s->file << " (" << reader_share(reader) << ")\n";
    return damaged.empty() ? kExitOk : kExitSalvaged;
  };
}

}  // namespace ivol::cli
