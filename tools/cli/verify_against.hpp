// ivol verify --against SOURCE FILE.ivol: re-checks a conversion against its
// source. The source's files must have the sizes and SHA-256 digests the
// file's provenance.sources recorded, and the volume's values must equal the
// source's (read by the converters' own readers), or differ by no more than
// the largest error the file records when the conversion was lossy.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace ivol::cli {

struct AgainstReport {
  std::string source;
  std::vector<std::string> source_problems;  // digests and sizes that differ, files missing or unrecorded
  bool values_compared = false;
  std::string values_skipped;  // why not, when not (a reconstruction's projections are not its values)
  double tolerance = 0.0;      // 0: lossless, every value equal
  std::uint64_t voxels = 0;
  std::uint64_t differing = 0;
  std::vector<std::string> first_differences;  // up to 10
  bool ok() const { return source_problems.empty() && differing == 0; }
  nlohmann::json to_json() const;
};

// A source that cannot be read is one of the report's source problems.
AgainstReport verify_against(const std::string& source, const std::string& file);

}  // namespace ivol::cli
