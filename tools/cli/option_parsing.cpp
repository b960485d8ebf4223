#include "option_parsing.hpp"

#include <cmath>
#include <sstream>
#include <vector>

#include "ivol/error.hpp"

namespace ivol::cli {
namespace {

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string part; std::getline(in, part, ',');) parts.push_back(part);
  return parts;
}

[[noreturn]] void bad(const char* option, const std::string& text, const char* expected) {
  throw Error(ErrorClass::InvalidArgument, std::string(option) + ": '" + text + "' is not " + expected);
}

}  // namespace

Dims parse_dims(const std::string& text, const char* option) {
  const auto parts = split(text);
  if (parts.size() != 3) bad(option, text, "X,Y,Z");
  Dims d{};
  for (int a = 0; a < 3; ++a) {
    try {
      const unsigned long v = std::stoul(parts[a]);
      if (v == 0 || v > (1ul << 31)) bad(option, text, "three sizes from 1 to 2^31");
      d[a] = static_cast<std::uint32_t>(v);
    } catch (const std::logic_error&) {
      bad(option, text, "X,Y,Z");
    }
  }
  return d;
}

Box parse_box(const std::string& text, const char* option) {
  const auto parts = split(text);
  if (parts.size() != 6) bad(option, text, "x0,y0,z0,x1,y1,z1");
  Box b;
  for (int i = 0; i < 6; ++i) {
    try {
      const unsigned long v = std::stoul(parts[i]);
      (i < 3 ? b.lo : b.hi)[i % 3] = static_cast<std::uint32_t>(v);
    } catch (const std::logic_error&) {
      bad(option, text, "x0,y0,z0,x1,y1,z1");
    }
  }
  return b;
}

std::array<double, 3> parse_triple(const std::string& text, const char* option, bool allow_single) {
  const auto parts = split(text);
  if (!(parts.size() == 3 || (allow_single && parts.size() == 1))) bad(option, text, "three numbers");
  std::array<double, 3> out{};
  for (int a = 0; a < 3; ++a) {
    try {
      out[a] = std::stod(parts[parts.size() == 1 ? 0 : a]);
    } catch (const std::logic_error&) {
      bad(option, text, "three numbers");
    }
    if (!std::isfinite(out[a])) bad(option, text, "finite numbers");
  }
  return out;
}

ValueEncoding parse_encoding(const std::string& text) {
  const auto e = ivol::parse_encoding(text);
  if (!e) bad("--encoding", text, "binary16, uint16 or float32");
  return *e;
}

void apply_geometry(convert::DenseVolume& volume, const std::string& voxel_size, const std::string& origin,
                    const std::string& unit) {
  if (!voxel_size.empty()) {
    volume.voxel_size = parse_triple(voxel_size, "--voxel-size", true);
    for (double v : volume.voxel_size)
      if (!(v > 0)) bad("--voxel-size", voxel_size, "positive");
    volume.has_geometry = true;
  }
  if (!origin.empty()) volume.origin = parse_triple(origin, "--origin", false), volume.has_geometry = true;
  if (!unit.empty()) volume.unit = unit, volume.has_geometry = true;
}

}  // namespace ivol::cli
