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
#include "png_image.hpp"

namespace ivol::cli {

Runner add_slice_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("slice", "Write one slice of an .ivol file as a PNG image");
  struct Settings {
    std::string file, axis = "z", output, window;
    std::uint32_t index = 0;
    unsigned level = 0;
    bool borders = false;
  };
  auto s = std::make_shared<Settings>();
  cmd->add_option("FILE", s->file, "The .ivol file")->required();
  cmd->add_option("--axis", s->axis, "x, y or z")->check(CLI::IsMember({"x", "y", "z"}))->capture_default_str();
  cmd->add_option("--index", s->index, "Slice index along the axis (at the chosen level)")->required();
  cmd->add_option("--level", s->level, "Level of detail: 1/2^K resolution");
  cmd->add_option("--window", s->window, "LO,HI: values mapped to black and white (default: the slice's range)");
  cmd->add_flag("--borders", s->borders, "Draw the borders of the octree's leaves in red");
  cmd->add_option("-o,--output", s->output, "The PNG image")->required();
  return [s, &global]() {
    Reader reader(s->file);
    const int axis = s->axis[0] - 'x';
    Box box = full_box(reader.layout().dims, s->level);
    if (s->index >= box.hi[axis])
      throw Error(ErrorClass::InvalidArgument,
                  "--index: " + std::to_string(s->index) + " is outside 0 .. " + std::to_string(box.hi[axis] - 1));
    box.lo[axis] = s->index;
    box.hi[axis] = s->index + 1;
    const std::vector<float> values = reader.read_box(box, s->level);
    // The image's axes: the two axes other than the slice's, the lower first.
    const int u = axis == 0 ? 1 : 0;
    const int v = axis == 2 ? 1 : 2;
    double lo, hi;
    if (!s->window.empty()) {
      const auto w = parse_triple(s->window + ",0", "--window", false);
      lo = w[0], hi = w[1];
    } else {
      lo = INFINITY, hi = -INFINITY;
      for (float f : values)
        if (std::isfinite(f)) lo = std::min<double>(lo, f), hi = std::max<double>(hi, f);
    }
    if (!(hi > lo)) hi = lo + 1;
    RgbImage image;
    image.width = box.hi[u] - box.lo[u];
    image.height = box.hi[v] - box.lo[v];
    image.pixels.resize(std::size_t{image.width} * image.height * 3);
    // values are [z][y][x] over the box; pixel (a, b) is (u = a, v = b).
    const std::uint64_t nx = box.hi[0] - box.lo[0], ny = box.hi[1] - box.lo[1];
    for (std::uint32_t b = 0; b < image.height; ++b)
      for (std::uint32_t a = 0; a < image.width; ++a) {
        std::uint32_t p[3] = {0, 0, 0};
        p[u] = a;
        p[v] = b;
        const float f = values[(p[2] * ny + p[1]) * nx + p[0]];
        const double t = std::clamp((f - lo) / (hi - lo), 0.0, 1.0);
        const auto g = static_cast<std::uint8_t>(std::lround(255 * (std::isnan(t) ? 0.0 : t)));
        image.set(a, image.height - 1 - b, g, g, g);  // v up, as on a drawing
      }
    std::uint64_t leaves = 0;
    if (s->borders)
      reader.visit_leaves(box, s->level, [&](const Box& region, double) {
        ++leaves;
        if (region.hi[u] - region.lo[u] < 2 && region.hi[v] - region.lo[v] < 2) return;  // single voxels: no border
        for (std::uint32_t a = region.lo[u]; a < region.hi[u]; ++a)
          for (std::uint32_t b : {region.lo[v], region.hi[v] - 1}) image.set(a, image.height - 1 - b, 220, 30, 30);
        for (std::uint32_t b = region.lo[v]; b < region.hi[v]; ++b)
          for (std::uint32_t a : {region.lo[u], region.hi[u] - 1}) image.set(a, image.height - 1 - b, 220, 30, 30);
      });
    write_png(image, s->output);
    if (!global.quiet) {
      std::cout << s->output << ": " << image.width << "x" << image.height << " slice " << s->axis << "=" << s->index
                << " of " << s->file << ", window " << lo << " .. " << hi;
      if (s->borders) std::cout << ", " << leaves << " leaves";
      std::cout << "\n";
    }
    return kExitOk;
  };
}

}  // namespace ivol::cli
