// One slice of an .ivol file as an image, grey values between a window,
// with the octree's leaf borders drawn in red on request (the paper's
// Figure 3, right): `ivol slice` and `ivol demo` draw it.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "ivol/reader.hpp"
#include "png_image.hpp"

namespace ivol::cli {

struct SliceImage {
  RgbImage image;
  double low = 0, high = 0;  // the window used
  bool finite = true;        // false: no window given and no finite value in the slice
  std::uint64_t leaves = 0;  // leaves met, when borders were drawn
};

// Slice `index` along `axis` (0 = x, 1 = y, 2 = z) at level of detail
// `level`; without a window, the slice's own range. Throws InvalidArgument
// for an index outside the volume.
SliceImage render_slice(Reader& reader, int axis, std::uint32_t index, unsigned level,
                        const std::optional<std::array<double, 2>>& window, bool borders);

}  // namespace ivol::cli
