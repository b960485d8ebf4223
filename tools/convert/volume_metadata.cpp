#include "volume_metadata.hpp"

#include <cmath>
#include <sstream>

#include "ivol/error.hpp"
#include "ivol/metadata.hpp"

namespace ivol::convert {
namespace {

std::string trim(const std::string& text) {
  const std::size_t b = text.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  return text.substr(b, text.find_last_not_of(" \t\r\n") + 1 - b);
}

nlohmann::json parse_provenance(const std::string& text) {
  if (text.empty()) return nlohmann::json::object();
  try {
    nlohmann::json j = nlohmann::json::parse(text);
    if (j.is_object()) return j;
  } catch (const nlohmann::json::exception&) {
  }
  // Not ours: keep the text rather than lose it.
  return nlohmann::json{{"source_provenance_text", text}};
}

std::array<double, 3> triple(const nlohmann::json& j, const std::string& where, const char* key) {
  if (!j.is_array() || j.size() != 3)
    throw Error(ErrorClass::Malformed, where + ": " + key + " is not an array of 3 numbers");
  std::array<double, 3> out{};
  for (int a = 0; a < 3; ++a) {
    if (!j[a].is_number()) throw Error(ErrorClass::Malformed, where + ": " + key + " is not an array of 3 numbers");
    out[a] = j[a].get<double>();
    if (!std::isfinite(out[a])) throw Error(ErrorClass::Malformed, where + ": " + key + " holds a non-finite number");
  }
  return out;
}

std::string text_of(const nlohmann::json& j, const std::string& where, const char* key) {
  if (!j.is_string()) throw Error(ErrorClass::Malformed, where + ": " + key + " is not a string");
  return j.get<std::string>();
}

std::string number(double v) {
  std::ostringstream out;
  out.precision(10);
  out << v;
  return out.str();
}

std::string from(const std::string& note) {
  return note.empty() ? "(default: none in the file)" : "(from " + note + ")";
}

class ReshapedSlabReader final : public SlabReader {
 public:
  ReshapedSlabReader(std::unique_ptr<SlabReader> inner, const DenseVolume& shape) : inner_(std::move(inner)) {
    shape_ = shape_of(shape);
  }
  void read(std::uint32_t z0, std::uint32_t count, void* out) override { inner_->read(z0, count, out); }
  bool thick_reads_pay() const override { return inner_->thick_reads_pay(); }

 private:
  std::unique_ptr<SlabReader> inner_;
};

}  // namespace

nlohmann::json metadata_json(const DenseVolume& shape) {
  nlohmann::json j = nlohmann::json::object();
  if (shape.has_geometry) {
    j["voxel_size"] = shape.voxel_size;
    j["origin"] = shape.origin;
    j["unit"] = shape.unit;
  }
  nlohmann::json value = nlohmann::json::object();
  if (!shape.quantity.empty()) value["quantity"] = shape.quantity;
  if (!shape.value_unit.empty()) value["unit"] = shape.value_unit;
  if (!value.empty()) j["value"] = value;
  if (!shape.provenance.empty()) j["provenance"] = parse_provenance(shape.provenance);
  return j;
}

void apply_metadata_json(const nlohmann::json& j, const std::string& where, DenseVolume& shape) {
  if (!j.is_object()) throw Error(ErrorClass::Malformed, where + ": the metadata is not a JSON object");
  if (j.contains("provenance")) {
    if (!j["provenance"].is_object()) throw Error(ErrorClass::Malformed, where + ": provenance is not an object");
    shape.provenance = j["provenance"].dump();
  }
  if (j.contains("value")) {
    const nlohmann::json& value = j["value"];
    if (!value.is_object()) throw Error(ErrorClass::Malformed, where + ": value is not an object");
    if (value.contains("quantity")) shape.quantity = text_of(value["quantity"], where, "value.quantity");
    if (value.contains("unit")) shape.value_unit = text_of(value["unit"], where, "value.unit");
  }
  if (j.contains("voxel_size") && !voxel_size_marked_unknown(shape.provenance)) {
    const std::array<double, 3> size = triple(j["voxel_size"], where, "voxel_size");
    for (double s : size)
      if (!(s > 0) || !std::isfinite(s))
        throw Error(ErrorClass::Malformed, where + ": voxel_size must be positive and finite");
    shape.voxel_size = size;
    shape.has_geometry = true;
    if (j.contains("origin")) shape.origin = triple(j["origin"], where, "origin");
    if (j.contains("unit")) shape.unit = text_of(j["unit"], where, "unit");
  }
}

bool voxel_size_marked_unknown(const std::string& provenance) {
  if (provenance.empty()) return false;
  try {
    const nlohmann::json j = nlohmann::json::parse(provenance);
    return j.is_object() && j.contains("voxel_size_known") && j["voxel_size_known"] == false;
  } catch (const nlohmann::json::exception&) {
    return false;
  }
}

nlohmann::json provenance_after_conversion(const DenseVolume& shape, const std::string& command,
                                           const std::string& input, const std::string& input_format) {
  nlohmann::json p = default_provenance();
  p["command"] = command;
  p["sources"] = {{{"path", input}, {"format", input_format}, {"sample_type", sample_type_name(shape.type)}}};
  if (!shape.provenance.empty()) p["derived_from"] = parse_provenance(shape.provenance);
  if (shape.has_geometry)
    p.erase("voxel_size_known");
  else
    p["voxel_size_known"] = false;
  return p;
}

std::vector<std::string> geometry_summary(const DenseVolume& s) {
  std::vector<std::string> lines;
  if (s.has_geometry) {
    lines.push_back("voxel size " + number(s.voxel_size[0]) + " x " + number(s.voxel_size[1]) + " x " +
                    number(s.voxel_size[2]) + " " + s.unit + " " + from(s.voxel_size_from));
    lines.push_back("origin " + number(s.origin[0]) + ", " + number(s.origin[1]) + ", " + number(s.origin[2]) + " " +
                    s.unit + " " + from(s.origin_from));
    lines.push_back("unit " + s.unit + " " + from(s.unit_from));
  } else {
    lines.push_back(
        "voxel size unknown (none in the file, no --voxel-size): recorded as unknown "
        "(provenance voxel_size_known = false)");
  }
  if (!s.quantity.empty() || !s.value_unit.empty())
    lines.push_back("values: " + (s.quantity.empty() ? std::string("(quantity not given)") : s.quantity) +
                    (s.value_unit.empty() ? std::string() : " in " + s.value_unit) + " " + from(s.quantity_from));
  for (const std::string& note : s.notes) lines.push_back(note);
  return lines;
}

std::unique_ptr<SlabReader> reshaped_slabs(std::unique_ptr<SlabReader> inner, const DenseVolume& shape) {
  return std::make_unique<ReshapedSlabReader>(std::move(inner), shape);
}

std::string normalise_length_unit(const std::string& text) {
  const std::string u = trim(text);
  if (u == "mm" || u == "millimeter" || u == "millimetre" || u == "millimeters" || u == "millimetres") return "mm";
  if (u == "um" || u == "micron" || u == "microns" || u == "\u00b5m" || u == "\u03bcm" || u == "\\u00B5m" ||
      u == "\\u00b5m" || u == "micrometer" || u == "micrometre" || u == "micrometers" || u == "micrometres")
    return "um";
  if (u == "nm" || u == "nanometer" || u == "nanometre" || u == "nanometers" || u == "nanometres") return "nm";
  if (u == "cm" || u == "centimeter" || u == "centimetre" || u == "centimeters" || u == "centimetres") return "cm";
  if (u == "m" || u == "meter" || u == "metre" || u == "meters" || u == "metres") return "m";
  if (u == "pixel" || u == "pixels" || u == "px") return "";
  return u;
}

double length_unit_factor(const std::string& unit, const std::string& to) {
  auto metres = [](const std::string& u) {
    if (u == "m") return 1.0;
    if (u == "cm") return 1e-2;
    if (u == "mm") return 1e-3;
    if (u == "um") return 1e-6;
    if (u == "nm") return 1e-9;
    return 0.0;
  };
  if (unit == to) return 1.0;
  const double a = metres(unit), b = metres(to);
  return a > 0 && b > 0 ? a / b : 0.0;
}

}  // namespace ivol::convert
