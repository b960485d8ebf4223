#include "report.hpp"

#include <unistd.h>

#include <cstdio>
#include <iostream>
#include <set>

#include "ivol/structures.hpp"
#include "option_parsing.hpp"

namespace ivol::cli {

std::string human_bytes(double bytes) {
  // Up to YiB: a valid file may describe 2^93 voxels (2^95 bytes as float32).
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB", "ZiB", "YiB"};
  double value = bytes;
  int unit = 0;
  while (value >= 1024.0 && unit < 8) value /= 1024.0, ++unit;
  char text[48];
  std::snprintf(text, sizeof text, unit == 0 ? "%.0f %s" : "%.1f %s", value, units[unit]);
  return text;
}

std::string human_bytes(std::uint64_t bytes) { return human_bytes(static_cast<double>(bytes)); }

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

void warn_if_fetched_whole(const Reader& reader, const std::string& command) {
  if (reader.io_stats().fetched_whole)
    std::cerr << command << ": warning: " << reader.path() << ": the server ignores range requests, so the whole file ("
              << human_bytes(reader.info().file_size)
              << ") was downloaded, and will be at every open; serve it with byte ranges to read only what is needed\n";
}

void require_level_within(unsigned level, const Reader& reader) {
  if (level > reader.layout().depth)
    throw UsageError("--level", std::to_string(level) + " is past the file's coarsest level " +
                                    std::to_string(reader.layout().depth));
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
  const bool bricked = v.kind == StructureKind::Bricked;
  // A bricked grid has no inner nodes: its rows are full resolution (level
  // 0, stream 3) and each stored level of detail (stream 7), in bricks.
  std::uint64_t bricked_blocks[64] = {};
  std::uint64_t bricked_bytes[64] = {};
  if (bricked)
    for (const BlockInfo& b : info.blocks)
      if ((b.stream == 3 || b.stream == 7) && b.level < 64) {
        ++bricked_blocks[b.level];
        bricked_bytes[b.level] += b.stored_size;
      }
  const std::uint64_t brick = std::uint64_t{1} << v.cell_log2;
  auto bricks_of = [&](const Dims& d) {
    return nlohmann::json::array({(d[0] + brick - 1) / brick, (d[1] + brick - 1) / brick, (d[2] + brick - 1) / brick});
  };
  for (unsigned l = 0; bricked && l <= v.depth && l < 64; ++l) {
    if (l > 0 && bricked_blocks[l] == 0) continue;
    const Dims d = lod_dims(v.dims, l);
    levels.push_back({{"level", l},
                      {"dims", {d[0], d[1], d[2]}},
                      {"bricks", bricks_of(d)},
                      {"blocks", bricked_blocks[l]},
                      {"bytes", bricked_bytes[l]}});
  }
  for (unsigned l = 0; !bricked && l <= v.depth; ++l) {
    levels.push_back({{"level", l},
                      {"voxel_side", std::uint64_t{1} << (v.depth - l)},
                      {"inner_nodes", v.inner_count[l]},
                      {"values", v.level_values(l)},
                      {"leaves", v.level_values(l) - v.inner_count[l]},
                      {"blocks", per_level_blocks[l]},
                      {"node_bytes", per_level_bytes[0][l]},
                      {"value_bytes", per_level_bytes[1][l]}});
  }
  // As float32: 4 bytes a voxel, which for 2^31 voxels a side is 2^95 bytes,
  // past 64 bits; then a JSON double (exact for powers of two).
  const double dense_bytes = 4.0 * voxel_count_approx(v.dims);
  const nlohmann::json dense_json =
      dense_bytes < 0x1p64 ? nlohmann::json(4 * voxel_count(v.dims)) : nlohmann::json(dense_bytes);
  // Decoded, an octree is its node words and values; a bricked grid every
  // voxel (a JSON double where the count passes 64 bits, as above).
  nlohmann::json in_memory = v.total_inner() * 8 + v.total_values() * encoding_width(v.encoding);
  nlohmann::json value_count = v.total_values();
  if (bricked) {
    const double voxels = voxel_count_approx(v.dims);
    const bool fits = voxels * encoding_width(v.encoding) < 0x1p64;
    value_count = fits ? nlohmann::json(voxel_count(v.dims)) : nlohmann::json(voxels);
    in_memory = fits ? nlohmann::json(voxel_count(v.dims) * encoding_width(v.encoding))
                     : nlohmann::json(voxels * encoding_width(v.encoding));
  }
  // The levels of detail a bricked grid stores (spec §8A.5, stream 7).
  std::set<unsigned> stored_levels;
  if (bricked)
    for (const BlockInfo& b : info.blocks)
      if (b.stream == 7) stored_levels.insert(b.level);
  return {
      {"stored_levels", std::vector<unsigned>(stored_levels.begin(), stored_levels.end())},
      {"file", reader.path()},
      {"format_version", std::to_string(info.version_major) + "." + std::to_string(info.version_minor)},
      {"structure", structure_name(v.kind)},
      {"nested_cell", v.kind == StructureKind::Nested ? (std::uint64_t{1} << v.cell_log2) : 0},
      {"brick", bricked ? brick : 0},
      {"bricks", bricked ? bricks_of(v.dims) : nlohmann::json::array()},
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
      {"dense_float32_bytes", dense_json},
      {"ratio_vs_float32", dense_bytes / static_cast<double>(info.file_size)},
      {"in_memory_bytes", in_memory},
      {"inner_nodes", v.total_inner()},
      {"values", value_count},
      {"blocks", info.blocks.size()},
      {"metadata_bytes", metadata_bytes},
      {"index_bytes", info.index_size},
      {"levels", levels},
      {"metadata", reader.metadata().to_json()},
  };
}

}  // namespace ivol::cli
