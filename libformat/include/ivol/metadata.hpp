// The metadata block (spec §11): what the values mean, where the voxels are,
// and where the data came from.
#pragma once

#include <array>
#include <nlohmann/json.hpp>
#include <string>

namespace ivol {

// Arrays and objects nest at most this deep in the metadata, the top-level
// object counting as 1 (spec §11); deeper text is refused (Malformed).
constexpr std::size_t kMaxMetadataDepth = 128;

struct Metadata {
  std::array<double, 3> voxel_size{1.0, 1.0, 1.0};
  std::string unit = "mm";
  std::array<double, 3> origin{0.0, 0.0, 0.0};  // centre of voxel (0, 0, 0)
  std::string quantity = "grey_value";          // e.g. "linear_attenuation"
  std::string value_unit;                       // e.g. "1/mm"; empty for grey values
  nlohmann::json structure = nlohmann::json::object();
  nlohmann::json provenance = nlohmann::json::object();
  nlohmann::json user = nlohmann::json::object();
  nlohmann::json other = nlohmann::json::object();  // keys this version does not know, kept

  nlohmann::json to_json() const;
  // Throws Error(Malformed) naming the offending key.
  static Metadata from_json(const nlohmann::json& json);
  // Parses the metadata block's bytes (UTF-8 JSON, no BOM, no duplicate keys,
  // nesting at most kMaxMetadataDepth).
  static Metadata parse(const std::string& text);
};

// The provenance entries ivol writes by default: software name and version,
// creation time (RFC 3339, UTC): now, or SOURCE_DATE_EPOCH's seconds when
// that is set (reproducible-builds.org), so that a file can be made again
// byte for byte.
nlohmann::json default_provenance();
// How deep arrays and objects nest in a JSON text (the top level counts 1),
// without parsing it; counting stops once past `limit`.
std::size_t json_nesting_depth(const std::string& text, std::size_t limit);
const char* library_version();

}  // namespace ivol
