// Parsing the comma-separated option values of the subcommands.
#pragma once

#include <string>

#include "dense_volume.hpp"
#include "ivol/geometry.hpp"

namespace ivol::cli {

Dims parse_dims(const std::string& text, const char* option);  // "X,Y,Z", each >= 1
Box parse_box(const std::string& text, const char* option);    // "x0,y0,z0,x1,y1,z1"
std::array<double, 3> parse_triple(const std::string& text, const char* option, bool allow_single);
ValueEncoding parse_encoding(const std::string& text);
// Overrides a volume's geometry with the options given (empty: keep).
void apply_geometry(convert::DenseVolume& volume, const std::string& voxel_size, const std::string& origin,
                    const std::string& unit);

}  // namespace ivol::cli
