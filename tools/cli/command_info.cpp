// ivol info FILE [--json]: what a file holds and how it is laid out.
#include <cstdio>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>

#include "commands.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "report.hpp"
#include "salvage_report.hpp"

namespace ivol::cli {

namespace {

// A file made from a damaged input (convert --salvage) says so where it is
// looked at, not only in its metadata.
std::string salvaged_line(const Metadata& m) {
  const auto salvage = m.provenance.find("salvage");
  if (!m.provenance.is_object() || salvage == m.provenance.end() || !salvage->is_object()) return {};
  std::string line = "  salvaged       from a damaged input: ";
  line += std::to_string(salvage->value("regions_filled", std::uint64_t{0})) +
          " region(s) filled from coarser levels or stored code 0";
  const auto metadata = salvage->find("metadata");
  if (metadata != salvage->end() && metadata->is_string() && metadata->get<std::string>() != "complete")
    line += "; input metadata " + metadata->get<std::string>();
  return line + " (provenance.salvage)\n";
}

// A file that does not hold every value of what it was written from says so
// where it is looked at, not only in its metadata: a keep rule's region
// and what stands outside it, or the encoding's rounding, and the largest
// error (structure.max_abs_error). Nothing for a lossless file.
std::string fidelity_line(const Metadata& m) {
  const nlohmann::json& s = m.structure;
  if (!s.is_object() || !s.contains("lossless") || !s["lossless"].is_boolean() || s["lossless"].get<bool>()) return {};
  std::ostringstream line;
  line << "  fidelity       not every value kept: ";
  const auto keep = s.find("keep");
  if (keep != s.end() && keep->is_object() && keep->contains("threshold") && keep->contains("margin")) {
    line << "full resolution above " << (*keep)["threshold"].dump()
         << (keep->value("threshold_method", "") == "otsu" ? " (Otsu's)" : "") << " and within "
         << (*keep)["margin"].dump() << " voxels of it, ";
    if (keep->value("outside", "") == "background" && keep->contains("background"))
      line << "one background value " << (*keep)["background"].dump() << " elsewhere";
    else
      line << "coarse leaves' averages elsewhere";
  } else {
    line << "the values rounded to the encoding";
  }
  if (s.contains("max_abs_error")) line << "; largest error " << s["max_abs_error"].dump();
  return line.str() + "\n";
}

// A bricked grid's stored levels of detail (spec §8A.5), a line of `info`.
std::string stored_levels_line(const nlohmann::json& d) {
  if (d["structure"].get<std::string>() != "bricked") return {};
  const auto& levels = d["stored_levels"];
  if (levels.empty()) return "  levels stored  none: every level of detail is summed from full resolution\n";
  std::string list;
  for (const auto& k : levels) list += (list.empty() ? "" : ", ") + std::to_string(k.get<unsigned>());
  return "  levels stored  " + list + " (levels of detail read from the file, not summed from full resolution)\n";
}

// "X x Y x Z" of a JSON triple of counts.
std::string times(const nlohmann::json& n) {
  return std::to_string(n[0].get<std::uint64_t>()) + " x " + std::to_string(n[1].get<std::uint64_t>()) + " x " +
         std::to_string(n[2].get<std::uint64_t>());
}

std::string in_memory_line(const nlohmann::json& d) {
  const std::string bytes = human_bytes(d["in_memory_bytes"].get<double>());
  if (d["structure"].get<std::string>() == "bricked")
    return "  in memory      " + bytes + " decoded (every voxel); " + times(d["bricks"]) +
           " bricks at full resolution\n";
  return "  in memory      " + bytes + " (" + d["inner_nodes"].dump() + " inner nodes, " + d["values"].dump() +
         " values)\n";
}

// A bricked grid's levels: full resolution and each stored level of detail.
void print_bricked_levels(const nlohmann::json& d) {
  std::cout << "  levels         level  dimensions            bricks           blocks   bytes\n";
  for (const auto& l : d["levels"]) {
    const std::string dims = times(l["dims"]);
    const std::string bricks = times(l["bricks"]);
    char line[200];
    std::snprintf(line, sizeof line, "                 %5u  %-20s  %-15s %8llu   %s\n", l["level"].get<unsigned>(),
                  dims.c_str(), bricks.c_str(), l["blocks"].get<unsigned long long>(),
                  human_bytes(l["bytes"].get<std::uint64_t>()).c_str());
    std::cout << line;
  }
}

}  // namespace

Runner add_info_command(CLI::App& app, const GlobalOptions& /*global*/) {
  auto* cmd = app.add_subcommand("info", "Show the structure, sizes, levels, blocks and metadata of an .ivol file");
  auto file = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  cmd->add_option("FILE", *file, "The .ivol file")->required();
  cmd->add_flag("--json", *json, "Print one JSON object (for machines)");
  return [file, json]() {
    std::optional<Reader> opened;
    try {
      opened.emplace(*file);
    } catch (const Error& e) {
      // A cut or damaged file: say what a salvaging read would get, then fail
      // as for any bad file (the error itself goes to standard error).
      if (!*json) {
        std::cout << *file << ": cannot be read as it is\n";
        print_salvage_prospect(std::cout, "  ", *file);
        throw;
      }
      // With --json, still one JSON object on standard output.
      std::ostringstream prospect;
      print_salvage_prospect(prospect, "", *file);
      nlohmann::json lines = nlohmann::json::array();
      std::istringstream text(prospect.str());
      for (std::string line; std::getline(text, line);)
        if (!line.empty()) lines.push_back(line);
      const nlohmann::json d = {{"path", *file},
                                {"status", "unreadable"},
                                {"error_class", error_class_name(e.error_class())},
                                {"error", e.what()},
                                {"salvage", lines}};
      std::cout << d.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
      throw;
    }
    Reader& reader = *opened;
    warn_if_fetched_whole(reader, "ivol info");
    const nlohmann::json d = describe_file(reader);
    if (*json) {
      std::cout << d.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
      return kExitOk;
    }
    const auto& dims = d["dimensions"];
    std::cout << d["file"].get<std::string>() << "\n"
              << "  format         .ivol " << d["format_version"].get<std::string>() << ", "
              << d["structure"].get<std::string>()
              << (d["brick"].get<std::uint64_t>()
                      ? ", bricks of " + std::to_string(d["brick"].get<std::uint64_t>()) + "^3"
                      : std::string())
              << " (depth " << d["depth"] << ")\n"
              << (d["structure_reason"].get<std::string>().empty()
                      ? std::string()
                      : "  chosen because " + d["structure_reason"].get<std::string>() + "\n")
              << stored_levels_line(d) << "  dimensions     " << dims[0] << " x " << dims[1] << " x " << dims[2]
              << " voxels of " << d["voxel_size"][0] << " x " << d["voxel_size"][1] << " x " << d["voxel_size"][2]
              << " " << d["unit"].get<std::string>() << "\n"
              << "  values         " << d["value_encoding"].get<std::string>() << " (physical = " << d["value_offset"]
              << " + " << d["value_scale"] << " x stored), " << reader.metadata().quantity
              << (reader.metadata().value_unit.empty() ? "" : " in " + reader.metadata().value_unit) << "\n"
              << "  file           " << human_bytes(d["file_bytes"].get<std::uint64_t>()) << " (dense float32 "
              << human_bytes(d["dense_float32_bytes"].get<double>()) << ", ratio "
              << d["ratio_vs_float32"].get<double>() << ")\n"
              << in_memory_line(d) << "  blocks         " << d["blocks"] << " (index "
              << human_bytes(d["index_bytes"].get<std::uint64_t>()) << ")\n"
              << fidelity_line(reader.metadata()) << salvaged_line(reader.metadata());
    if (d["structure"].get<std::string>() == "bricked") {
      print_bricked_levels(d);
      std::cout << "  metadata       " << d["metadata"].dump() << "\n";
      return kExitOk;
    }
    std::cout << "  levels         level  side   inner nodes        leaves   blocks   bytes\n";
    for (const auto& l : d["levels"]) {
      char line[160];
      std::snprintf(line, sizeof line, "                 %5u %5llu %13llu %13llu %8llu   %s\n",
                    l["level"].get<unsigned>(), l["voxel_side"].get<unsigned long long>(),
                    l["inner_nodes"].get<unsigned long long>(), l["leaves"].get<unsigned long long>(),
                    l["blocks"].get<unsigned long long>(),
                    human_bytes(l["node_bytes"].get<std::uint64_t>() + l["value_bytes"].get<std::uint64_t>()).c_str());
      std::cout << line;
    }
    std::cout << "  metadata       " << d["metadata"].dump() << "\n";
    return kExitOk;
  };
}

}  // namespace ivol::cli
