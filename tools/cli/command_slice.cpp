// ivol slice FILE --axis z --index N -o out.png: an image of one slice, with
// the octree's leaf borders drawn over it on request (like the paper's
// Figure 3, right), so people see where resolution was kept.
#include <algorithm>
#include <cmath>
#include <iostream>

#include "commands.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "png_image.hpp"
#include "report.hpp"
#include "signal_cleanup.hpp"
#include "slice_image.hpp"

namespace ivol::cli {

Runner add_slice_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("slice", "Write one slice of an .ivol file as a PNG image");
  struct Settings {
    std::string file, axis = "z", output, window;
    std::uint32_t index = 0;
    unsigned level = 0;
    bool borders = false;
    bool force = false;
  };
  auto s = std::make_shared<Settings>();
  cmd->add_option("FILE", s->file, "The .ivol file")->required();
  cmd->add_option("--axis", s->axis, "x, y or z")->check(CLI::IsMember({"x", "y", "z"}))->capture_default_str();
  cmd->add_option("--index", s->index, "Slice index along the axis (at the chosen level)")
      ->required()
      ->check(whole_number());
  cmd->add_option("--level", s->level, "Level of detail: 1/2^K resolution")->check(whole_number());
  cmd->add_option("--window", s->window, "LO,HI: values mapped to black and white (default: the slice's range)")
      ->check(checked([](const std::string& v) { parse_window(v, "--window"); }));
  cmd->add_flag("--borders", s->borders, "Draw the borders of the octree's leaves in red");
  cmd->add_option("-o,--output", s->output, "The PNG image (.png)")->required();
  cmd->add_flag("-f,--force", s->force, "Replace the image if it exists");
  return [s, &global]() {
    // slice writes PNG only: the name must say so (s.jpg would hold PNG bytes).
    if (lower_extension(s->output) != ".png") throw UsageError("-o", "'" + s->output + "' is not a .png name");
    check_output(s->output, "-o", {s->file}, s->force);
    remove_temporaries_on_signal(s->output);
    Reader reader(s->file);
    warn_if_fetched_whole(reader, "ivol slice");
    const int axis = s->axis[0] - 'x';
    std::optional<std::array<double, 2>> window;
    if (!s->window.empty()) window = parse_window(s->window, "--window");
    require_level_within(s->level, reader);
    const Dims extent = lod_dims(reader.layout().dims, s->level);
    if (s->index >= extent[axis])
      throw UsageError("--index", std::to_string(s->index) + " is outside the volume (" + std::to_string(extent[axis]) +
                                      " slices along " + s->axis + " at level " + std::to_string(s->level) + ")");
    const SliceImage slice = render_slice(reader, axis, s->index, s->level, window, s->borders);
    const RgbImage& image = slice.image;
    const double lo = slice.low, hi = slice.high;
    const std::uint64_t leaves = slice.leaves;
    write_png(image, s->output);
    if (!global.quiet) {
      std::cout << s->output << ": " << image.width << "x" << image.height << " slice " << s->axis << "=" << s->index
                << " of " << s->file << ", window " << lo << " .. " << hi;
      if (!slice.finite) std::cout << " (no finite value in the slice: +inf white, -inf and NaN black)";
      if (s->borders) std::cout << ", " << leaves << " leaves";
      std::cout << "\n";
    }
    return kExitOk;
  };
}

}  // namespace ivol::cli
