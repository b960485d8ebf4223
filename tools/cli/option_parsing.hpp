// Parsing option values: one strict parser per kind of value, shared by every
// command. A value that does not parse is a bad command line (UsageError, exit
// 1), found while CLI11 parses (`->check(checked(...))`) so before any work.
#pragma once

#include <CLI/CLI.hpp>
#include <array>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "dense_volume.hpp"
#include "ivol/encoding.hpp"
#include "ivol/geometry.hpp"
#include "ivol_io.hpp"

namespace ivol::cli {

// A bad command line: an option's value, a missing or conflicting option, an
// output the rules refuse. main() turns it into exit code 1.
class UsageError : public std::runtime_error {
 public:
  UsageError(const std::string& option, const std::string& problem)
      : std::runtime_error(option.empty() ? problem : option + ": " + problem), problem_(problem) {}
  const std::string& problem() const { return problem_; }

 private:
  std::string problem_;
};

// The whole text must be the number: "0.05mm", "1e", "" and "nan" are refused.
double parse_number(const std::string& text, const char* option);
// Digits only: "-1", "+3", "2.0" and "0x10" are refused.
std::uint64_t parse_count(const std::string& text, const char* option);
// least..most comma-separated finite numbers.
std::vector<double> parse_numbers(const std::string& text, const char* option, std::size_t least, std::size_t most);

Dims parse_dims(const std::string& text, const char* option);  // "X,Y,Z", each 1 .. 2^31
Box parse_box(const std::string& text, const char* option);    // "x0,y0,z0,x1,y1,z1", lo < hi on every axis
std::array<double, 3> parse_triple(const std::string& text, const char* option, bool allow_single);
std::array<double, 2> parse_window(const std::string& text, const char* option);  // "LO,HI", LO < HI
convert::KeepRule parse_keep(const std::string& text, const char* option);        // threshold=T|otsu,margin=M
ValueEncoding parse_encoding(const std::string& text);
convert::SampleType parse_sample_type(const std::string& text, const char* option);  // u8 u16 i16 f16 f32

// A CLI11 check that runs `parse` on the option's value at parse time; the
// parser's UsageError becomes CLI11's validation error (exit 1).
CLI::Validator checked(const std::function<void(const std::string&)>& parse, const std::string& description = "");

// Digits only, for CLI11's unsigned options: CLI11 itself turns "-4" into
// 2^64 - 4 for a 64-bit one.
CLI::Validator whole_number();
// A size in MiB: a whole number from 1 whose bytes fit 64 bits (below 2^44),
// for --memory and --device-memory, where 0 would quietly mean "default".
CLI::Validator mebibytes();
// A finite number within [low, high] (open at low when `open_low`): CLI11
// itself takes "nan" and "inf" for a double, and NaN passes CLI::Range.
CLI::Validator number_in(double low, double high, bool open_low = false);

// Overrides a volume's geometry with the options given (empty: keep).
void apply_geometry(convert::DenseVolume& volume, const std::string& voxel_size, const std::string& origin,
                    const std::string& unit);

}  // namespace ivol::cli
