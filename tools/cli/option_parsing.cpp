#include "option_parsing.hpp"

#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

namespace ivol::cli {
namespace {

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> parts;
  std::size_t at = 0;
  while (true) {
    const std::size_t comma = text.find(',', at);
    parts.push_back(text.substr(at, comma == std::string::npos ? std::string::npos : comma - at));
    if (comma == std::string::npos) return parts;
    at = comma + 1;
  }
}

[[noreturn]] void bad(const char* option, const std::string& text, const std::string& expected) {
  throw UsageError(option, "'" + text + "' is not " + expected);
}

}  // namespace

double parse_number(const std::string& text, const char* option) {
  double value = 0.0;
  const char* end = text.data() + text.size();
  // from_chars: no locale, no leading spaces or '+', and it says how much it read.
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (text.empty() || ec != std::errc() || ptr != end || !std::isfinite(value)) bad(option, text, "a number");
  return value;
}

std::uint64_t parse_count(const std::string& text, const char* option) {
  std::uint64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (text.empty() || ec != std::errc() || ptr != end) bad(option, text, "a whole number of 0 or more");
  return value;
}

std::vector<double> parse_numbers(const std::string& text, const char* option, std::size_t least, std::size_t most) {
  const auto parts = split(text);
  if (parts.size() < least || parts.size() > most)
    throw UsageError(option, "'" + text + "' needs " + std::to_string(least) +
                                 (most > least ? " or " + std::to_string(most) : std::string()) +
                                 " comma-separated numbers");
  std::vector<double> values;
  for (const std::string& p : parts) {
    if (p.empty()) bad(option, text, "a list of numbers");
    values.push_back(parse_number(p, option));
  }
  return values;
}

Dims parse_dims(const std::string& text, const char* option) {
  const auto parts = split(text);
  if (parts.size() != 3) bad(option, text, "X,Y,Z");
  Dims d{};
  for (int a = 0; a < 3; ++a) {
    const std::uint64_t v = parse_count(parts[a], option);
    if (v == 0 || v > (1ull << 31)) bad(option, text, "three sizes from 1 to 2^31");
    d[a] = static_cast<std::uint32_t>(v);
  }
  return d;
}

Box parse_box(const std::string& text, const char* option) {
  const auto parts = split(text);
  if (parts.size() != 6) bad(option, text, "x0,y0,z0,x1,y1,z1");
  Box b;
  for (int i = 0; i < 6; ++i) {
    const std::uint64_t v = parse_count(parts[i], option);
    if (v > 0xffffffffull) bad(option, text, "x0,y0,z0,x1,y1,z1 within 32 bits");
    (i < 3 ? b.lo : b.hi)[i % 3] = static_cast<std::uint32_t>(v);
  }
  for (int a = 0; a < 3; ++a)
    if (b.lo[a] >= b.hi[a]) bad(option, text, "a box: each x1,y1,z1 must exceed its x0,y0,z0 (half-open)");
  return b;
}

std::array<double, 3> parse_triple(const std::string& text, const char* option, bool allow_single) {
  const auto v = parse_numbers(text, option, allow_single ? 1 : 3, 3);
  if (v.size() == 2) bad(option, text, allow_single ? "N or X,Y,Z" : "X,Y,Z");
  return v.size() == 1 ? std::array<double, 3>{v[0], v[0], v[0]} : std::array<double, 3>{v[0], v[1], v[2]};
}

std::array<double, 2> parse_window(const std::string& text, const char* option) {
  const auto v = parse_numbers(text, option, 2, 2);
  if (!(v[0] < v[1])) bad(option, text, "LO,HI with LO below HI");
  return {v[0], v[1]};
}

convert::KeepRule parse_keep(const std::string& text, const char* option) {
  convert::KeepRule rule;
  bool have_threshold = false, have_margin = false;
  for (const std::string& item : split(text)) {
    const std::size_t eq = item.find('=');
    const std::string key = item.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : item.substr(eq + 1);
    if (key == "threshold" && !have_threshold) {
      have_threshold = true;
      if (value == "otsu")
        rule.otsu = true;
      else
        rule.threshold = static_cast<float>(parse_number(value, option));
    } else if (key == "margin" && !have_margin) {
      have_margin = true;
      const std::uint64_t m = parse_count(value, option);
      if (m > 4096) bad(option, text, "a margin of 0 to 4096 voxels");
      rule.margin = static_cast<unsigned>(m);
    } else {
      bad(option, text, "threshold=VALUE|otsu[,margin=VOXELS] (each once)");
    }
  }
  if (!have_threshold) throw UsageError(option, "threshold=VALUE|otsu is required");
  return rule;
}

ValueEncoding parse_encoding(const std::string& text) {
  const auto e = ivol::parse_encoding(text);
  if (!e) bad("--encoding", text, "binary16, uint16 or float32");
  return *e;
}

convert::SampleType parse_sample_type(const std::string& text, const char* option) {
  convert::SampleType type{};
  if (!convert::parse_sample_type(text, type)) bad(option, text, "u8, u16, i16, f16 or f32");
  return type;
}

CLI::Validator checked(const std::function<void(const std::string&)>& parse, const std::string& description) {
  return CLI::Validator(
      [parse](std::string& value) -> std::string {
        try {
          parse(value);
        } catch (const UsageError& e) {
          return e.problem();
        }
        return {};
      },
      description);
}

CLI::Validator whole_number() {
  return checked([](const std::string& v) { parse_count(v, ""); });
}

CLI::Validator mebibytes() {
  return checked([](const std::string& v) {
    const std::uint64_t mib = parse_count(v, "");
    if (mib == 0) throw UsageError("", "'" + v + "' MiB is no memory: give 1 or more, or leave the option out");
    if (mib >= std::uint64_t{1} << 44)
      throw UsageError("", "'" + v + "' MiB is more bytes than 64 bits hold (at most 17592186044415)");
  });
}

CLI::Validator number_in(double low, double high, bool open_low) {
  return checked([=](const std::string& v) {
    const double x = parse_number(v, "");
    if (x < low || x > high || (open_low && x == low)) {
      std::ostringstream range;
      range << (open_low ? "(" : "[") << low << ", " << high << "]";
      throw UsageError("", "'" + v + "' is not in " + range.str());
    }
  });
}

void apply_geometry(convert::DenseVolume& volume, const std::string& voxel_size, const std::string& origin,
                    const std::string& unit) {
  if (!voxel_size.empty()) {
    volume.voxel_size = parse_triple(voxel_size, "--voxel-size", true);
    for (double v : volume.voxel_size)
      if (!(v > 0)) bad("--voxel-size", voxel_size, "positive");
    volume.has_geometry = true;
    volume.voxel_size_from = "--voxel-size";
  }
  // Origin and unit alone do not make a voxel size known.
  if (!origin.empty()) volume.origin = parse_triple(origin, "--origin", false), volume.origin_from = "--origin";
  if (!unit.empty()) volume.unit = unit, volume.unit_from = "--unit";
}

}  // namespace ivol::cli
