// One function checks a whole file: every checksum and every structural rule
// of the spec. `ivol verify`, the fuzzers and the tests call it.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "ivol/error.hpp"
#include "ivol/reader.hpp"

namespace ivol {

struct CheckProblem {
  ErrorClass error_class;
  std::string message;  // names the part of the file, the offset and what is wrong
};

struct CheckReport {
  std::vector<CheckProblem> problems;
  std::optional<FileInfo> info;  // present when the header, footer and index could be read
  std::size_t blocks_checked = 0;
  std::size_t blocks_damaged = 0;
  bool tree_checked = false;  // structure and every inner average verified
  bool ok() const { return problems.empty(); }
};

// Never throws for a damaged file: every problem goes into the report. Each
// block is checked on its own, so one damaged block does not hide another.
CheckReport check_file(const std::string& path);

}  // namespace ivol
