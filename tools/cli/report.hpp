// Formatting numbers and file summaries for people and for machines.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "ivol/reader.hpp"
#include "ivol_io.hpp"

namespace ivol::cli {

std::string human_bytes(std::uint64_t bytes);  // "12.3 MiB"
std::string human_bytes(double bytes);         // beyond 2^64 too: "32768.0 YiB"
// A progress bar on stderr, a few updates a second, only when stderr is a
// terminal and not --quiet; otherwise nothing.
convert::Progress progress_bar(const std::string& label, bool quiet);

// On stderr, when the server of a remote file ignored range requests and
// sent it whole: every open downloads it whole again.
void warn_if_fetched_whole(const Reader& reader, const std::string& command);
// --level past the file's coarsest level: a bad command line (exit 1), as
// every out-of-range option value is (README, exit codes).
void require_level_within(unsigned level, const Reader& reader);

// Everything `ivol info` reports, as JSON.
nlohmann::json describe_file(Reader& reader);

}  // namespace ivol::cli
