// What a salvaging open of a damaged or cut .ivol file found (spec §18), in
// words: `extract --salvage`, `info` and `verify` print it.
#pragma once

#include <ostream>
#include <string>

#include "ivol/reader.hpp"

namespace ivol::cli {

void print_salvage(std::ostream& out, const std::string& indent, const SalvageInfo& salvage,
                   const VolumeLayout& layout);

// For a file that cannot be opened: tries a salvaging open and prints what
// could be salvaged, or why nothing can. Never throws.
void print_salvage_prospect(std::ostream& out, const std::string& indent, const std::string& file);

}  // namespace ivol::cli
