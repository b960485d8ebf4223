#include "ivol/metadata.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <set>
#include <vector>

#include "ivol/error.hpp"

namespace ivol {
namespace {

using nlohmann::json;

[[noreturn]] void fail(const std::string& what) { throw Error(ErrorClass::Malformed, "metadata: " + what); }

std::array<double, 3> triple(const json& j, const char* key, bool positive) {
  const auto it = j.find(key);
  if (it == j.end()) fail(std::string("required key \"") + key + "\" is missing");
  if (!it->is_array() || it->size() != 3) fail(std::string("\"") + key + "\" must be an array of 3 numbers");
  std::array<double, 3> out{};
  for (std::size_t a = 0; a < 3; ++a) {
    const json& v = (*it)[a];
    if (!v.is_number()) fail(std::string("\"") + key + "\" must be an array of 3 numbers");
    out[a] = v.get<double>();
    if (!std::isfinite(out[a]) || (positive && out[a] <= 0))
      fail(std::string("\"") + key + "\"[" + std::to_string(a) + "] must be a " + (positive ? "positive" : "finite") +
           " number");
  }
  return out;
}

std::string string_key(const json& j, const char* key, const char* where) {
  const auto it = j.find(key);
  if (it == j.end()) fail(std::string("required key \"") + where + key + "\" is missing");
  if (!it->is_string()) fail(std::string("\"") + where + key + "\" must be a string");
  return it->get<std::string>();
}

json optional_object(const json& j, const char* key) {
  const auto it = j.find(key);
  if (it == j.end()) return json::object();
  if (!it->is_object()) fail(std::string("\"") + key + "\" must be an object");
  return *it;
}

}  // namespace

const char* library_version() { return IVOL_VERSION_STRING; }

// A scan of the bytes, before any parser sees them: nlohmann's parser, the
// copies of Metadata and whoever prints it all recurse once per level, and
// 100 000 brackets (a few hundred bytes) overflow the stack. Stops counting
// past `limit`.
std::size_t json_nesting_depth(const std::string& text, std::size_t limit) {
  std::size_t depth = 0;
  std::size_t deepest = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\')
        ++i;  // the escaped character cannot end the string
      else if (c == '"')
        in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
      if (deepest > limit) return deepest;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return deepest;
}

json default_provenance() {
  char created[32];
  std::time_t now = std::time(nullptr);
  if (const char* epoch = std::getenv("SOURCE_DATE_EPOCH")) {
    char* end = nullptr;
    const long long seconds = std::strtoll(epoch, &end, 10);
    if (end != epoch && *end == '\0' && seconds >= 0) now = static_cast<std::time_t>(seconds);
  }
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::strftime(created, sizeof created, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return json{{"software", {{"name", "ivol"}, {"version", library_version()}}}, {"created", created}};
}

json Metadata::to_json() const {
  json j = other;
  j["voxel_size"] = voxel_size;
  j["unit"] = unit;
  j["origin"] = origin;
  j["value"] = json{{"quantity", quantity}};
  if (!value_unit.empty()) j["value"]["unit"] = value_unit;
  if (!structure.empty()) j["structure"] = structure;
  if (!provenance.empty()) j["provenance"] = provenance;
  if (!user.empty()) j["user"] = user;
  return j;
}

Metadata Metadata::from_json(const json& j) {
  if (!j.is_object()) fail("the top level must be a JSON object");
  Metadata m;
  m.voxel_size = triple(j, "voxel_size", true);
  m.origin = triple(j, "origin", false);
  m.unit = string_key(j, "unit", "");
  const auto value = j.find("value");
  if (value == j.end()) fail("required key \"value\" is missing");
  if (!value->is_object()) fail("\"value\" must be an object");
  m.quantity = string_key(*value, "quantity", "value.");
  if (value->contains("unit")) m.value_unit = string_key(*value, "unit", "value.");
  m.structure = optional_object(j, "structure");
  m.provenance = optional_object(j, "provenance");
  m.user = optional_object(j, "user");
  for (const auto& [key, v] : j.items()) {
    if (key != "voxel_size" && key != "origin" && key != "unit" && key != "value" && key != "structure" &&
        key != "provenance" && key != "user")
      m.other[key] = v;
  }
  return m;
}

Metadata Metadata::parse(const std::string& text) {
  if (text.size() >= 3 && static_cast<unsigned char>(text[0]) == 0xEF && static_cast<unsigned char>(text[1]) == 0xBB &&
      static_cast<unsigned char>(text[2]) == 0xBF)
    fail("the JSON text starts with a byte-order mark");
  if (json_nesting_depth(text, kMaxMetadataDepth) > kMaxMetadataDepth)
    fail("arrays and objects are nested deeper than " + std::to_string(kMaxMetadataDepth) + " levels");
  // Track the keys of every open object to refuse duplicates, which
  // nlohmann::json would otherwise resolve silently.
  std::vector<std::set<std::string>> open_objects;
  std::string duplicate;
  const json::parser_callback_t on_event = [&](int /*depth*/, json::parse_event_t event, json& parsed) {
    switch (event) {
      case json::parse_event_t::object_start:
        open_objects.emplace_back();
        break;
      case json::parse_event_t::object_end:
        if (!open_objects.empty()) open_objects.pop_back();
        break;
      case json::parse_event_t::key:
        if (!open_objects.empty() && !open_objects.back().insert(parsed.get<std::string>()).second && duplicate.empty())
          duplicate = parsed.get<std::string>();
        break;
      default:
        break;
    }
    return true;
  };
  json j;
  try {
    j = json::parse(text, on_event, /*allow_exceptions=*/true, /*ignore_comments=*/false);
  } catch (const json::exception& e) {
    fail(std::string("not valid UTF-8 JSON: ") + e.what());
  }
  if (!duplicate.empty()) fail("key \"" + duplicate + "\" appears twice in one object");
  return from_json(j);
}

}  // namespace ivol
