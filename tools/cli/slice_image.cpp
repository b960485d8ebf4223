#include "slice_image.hpp"

#include <algorithm>
#include <cmath>

#include "ivol/error.hpp"
#include "sizes.hpp"

namespace ivol::cli {

SliceImage render_slice(Reader& reader, int axis, std::uint32_t index, unsigned level,
                        const std::optional<std::array<double, 2>>& window, bool borders) {
  Box box = full_box(reader.layout().dims, level);
  if (index >= box.hi[axis])
    throw Error(ErrorClass::InvalidArgument,
                "--index: " + std::to_string(index) + " is outside 0 .. " + std::to_string(box.hi[axis] - 1));
  box.lo[axis] = index;
  box.hi[axis] = index + 1;
  // The slice as float32 and as RGB pixels, before anything is read: a
  // valid file may have 2^31 voxels a side (a slice of 2^62 voxels).
  const double pixels = voxel_count_approx(Dims{box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]});
  if (pixels * (4 + 3) > static_cast<double>(convert::kDefaultMemoryBytes))
    throw Error(ErrorClass::LimitExceeded,
                reader.path() + ": a slice of " + std::to_string(box.hi[0] - box.lo[0]) + "x" +
                    std::to_string(box.hi[1] - box.lo[1]) + "x" + std::to_string(box.hi[2] - box.lo[2]) +
                    " voxels at level " + std::to_string(level) + " needs " + convert::mib_text(pixels * (4 + 3)) +
                    " as float32 values and RGB pixels, more than the " +
                    convert::mib_text(convert::kDefaultMemoryBytes) + " an image may take (--level K: a coarser one)");
  const std::vector<float> values = reader.read_box(box, level);
  // The image's axes: the two axes other than the slice's, the lower first.
  const int u = axis == 0 ? 1 : 0;
  const int v = axis == 2 ? 1 : 2;
  SliceImage slice;
  double lo, hi;
  if (window) {
    lo = (*window)[0], hi = (*window)[1];
  } else {
    lo = INFINITY, hi = -INFINITY;
    for (float f : values)
      if (std::isfinite(f)) lo = std::min<double>(lo, f), hi = std::max<double>(hi, f);
  }
  // A slice of infinities and NaNs only has no range of its own: 0 .. 1
  // then, so that +inf still shows white and -inf black, and the summary
  // says so rather than print a window of inf .. inf.
  slice.finite = std::isfinite(lo);
  if (!slice.finite) lo = 0, hi = 1;
  if (!(hi > lo)) hi = lo + 1;
  RgbImage& image = slice.image;
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
  if (borders)
    reader.visit_leaves(box, level, [&](const Box& region, double) {
      ++slice.leaves;
      if (region.hi[u] - region.lo[u] < 2 && region.hi[v] - region.lo[v] < 2) return;  // single voxels: no border
      for (std::uint32_t a = region.lo[u]; a < region.hi[u]; ++a)
        for (std::uint32_t b : {region.lo[v], region.hi[v] - 1}) image.set(a, image.height - 1 - b, 220, 30, 30);
      for (std::uint32_t b = region.lo[v]; b < region.hi[v]; ++b)
        for (std::uint32_t a : {region.lo[u], region.hi[u] - 1}) image.set(a, image.height - 1 - b, 220, 30, 30);
    });
  slice.low = lo;
  slice.high = hi;
  return slice;
}

}  // namespace ivol::cli
