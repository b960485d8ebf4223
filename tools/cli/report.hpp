// Formatting numbers and file summaries for people and for machines.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "ivol/reader.hpp"

namespace ivol::cli {

std::string human_bytes(std::uint64_t bytes);  // "12.3 MiB"
// Everything `ivol info` reports, as JSON.
nlohmann::json describe_file(Reader& reader);

}  // namespace ivol::cli
