#include "report.hpp"

#include <unistd.h>

#include <cstdio>

#include "ivol/structures.hpp"

namespace ivol::cli {

std::string human_bytes(std::uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 4) value /= 1024.0, ++unit;
  char text[32];
  std::snprintf(text, sizeof text, unit == 0 ? "%.0f %s" : "%.1f %s", value, units[unit]);
  return text;
}

convert::Progress progress_bar(const std::string& label, bool quiet) {
  if (quiet || !isatty(STDERR_FILENO)) return {};
  return [label](std::uint64_t done, std::uint64_t total) {
    const int width = 30;
    const int filled = total ? static_cast<int>(width * done / total) : width;
    std::fprintf(stderr, "\r%s [%.*s%*s] %3d%%", label.c_str(), filled, "##############################",
                 width - filled, "", total ? static_cast<int>(100 * done / total) : 100);
    if (done >= total) std::fputs("\n", stderr);
    std::fflush(stderr);
  };
}

nlohmann::json describe_file(Reader& reader) {
  const FileInfo& info = reader.info();
  const VolumeLayout& v = info.layout;
  nlohmann::json levels = nlohmann::json::array();
  std::uint64_t per_level_bytes[2][32] = {};
  std::uint64_t per_level_blocks[32] = {};
  std::uint64_t metadata_bytes = 0;
  for (const BlockInfo& b : info.blocks) {
    if (b.stream == 1) metadata_bytes += b.stored_size;
    if (b.stream == 2 || b.stream == 3) {
      per_level_bytes[b.stream - 2][b.level] += b.stored_size;
      ++per_level_blocks[b.level];
    }
  }
  for (unsigned l = 0; l <= v.depth; ++l) {
    levels.push_back({{"level", l},
                      {"voxel_side", std::uint64_t{1} << (v.depth - l)},
                      {"inner_nodes", v.inner_count[l]},
                      {"values", v.level_values(l)},
                      {"leaves", v.level_values(l) - v.inner_count[l]},
                      {"blocks", per_level_blocks[l]},
                      {"node_bytes", per_level_bytes[0][l]},
                      {"value_bytes", per_level_bytes[1][l]}});
  }
  const std::uint64_t voxels = voxel_count(v.dims);
  const std::uint64_t in_memory = v.total_inner() * 8 + v.total_values() * encoding_width(v.encoding);
  return {
      {"file", reader.path()},
      {"format_version", std::to_string(info.version_major) + "." + std::to_string(info.version_minor)},
      {"structure", structure_name(v.kind)},
      {"nested_cell", v.kind == StructureKind::Nested ? (std::uint64_t{1} << v.cell_log2) : 0},
      {"brick", v.kind == StructureKind::Bricked ? (std::uint64_t{1} << v.cell_log2) : 0},
      {"structure_reason", reader.metadata().structure.is_object()
                               ? reader.metadata().structure.value("chosen_because", std::string())
                               : std::string()},
      {"dimensions", {v.dims[0], v.dims[1], v.dims[2]}},
      {"depth", v.depth},
      {"value_encoding", encoding_name(v.encoding)},
      {"value_scale", v.value_scale},
      {"value_offset", v.value_offset},
      {"voxel_size", reader.metadata().voxel_size},
      {"unit", reader.metadata().unit},
      {"origin", reader.metadata().origin},
      {"file_bytes", info.file_size},
      {"dense_float32_bytes", voxels * 4},
      {"ratio_vs_float32", static_cast<double>(voxels * 4) / static_cast<double>(info.file_size)},
      {"in_memory_bytes", in_memory},
      {"inner_nodes", v.total_inner()},
      {"values", v.total_values()},
      {"blocks", info.blocks.size()},
      {"metadata_bytes", metadata_bytes},
      {"index_bytes", info.index_size},
      {"levels", levels},
      {"metadata", reader.metadata().to_json()},
  };
}

}  // namespace ivol::cli
