#include "verify_against.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "fixity.hpp"
#include "formats.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"

namespace ivol::cli {
namespace {

namespace fs = std::filesystem;

std::string file_name(const std::string& path) { return fs::path(path).filename().string(); }

// Compares the source's files with the recorded entries; returns the entry
// that describes how to read the source (format, sample type...), or null.
const nlohmann::json* compare_digests(const std::string& source, const nlohmann::json& recorded,
                                      std::vector<std::string>& problems) {
  std::vector<const nlohmann::json*> files;
  const nlohmann::json* summary = nullptr;
  for (const nlohmann::json& e : recorded) {
    if (e.contains("manifest_sha256")) summary = &e;
    if (e.contains("sha256")) files.push_back(&e);
  }
  const std::vector<std::string> paths = input_files(source);
  std::vector<FileDigest> digests;
  for (const std::string& p : paths) {
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) {
      problems.push_back(p + ": missing or not a file");
      continue;
    }
    digests.push_back(digest_file(p));
  }
  if (summary && fs::is_directory(source)) {
    std::uint64_t bytes = 0;
    for (const FileDigest& d : digests) bytes += d.bytes;
    if ((*summary)["files"].get<std::uint64_t>() != digests.size())
      problems.push_back(source + ": " + std::to_string(digests.size()) + " files, recorded " +
                         std::to_string((*summary)["files"].get<std::uint64_t>()));
    if ((*summary)["bytes"].get<std::uint64_t>() != bytes)
      problems.push_back(source + ": " + std::to_string(bytes) + " bytes in all, recorded " +
                         std::to_string((*summary)["bytes"].get<std::uint64_t>()));
    const std::string now = manifest_digest(digests, source);
    if ((*summary)["manifest_sha256"].get<std::string>() != now)
      problems.push_back(source + ": the files' digests differ from the recorded ones (manifest sha256 " + now +
                         ", recorded " + (*summary)["manifest_sha256"].get<std::string>() + ")");
    return summary;
  }
  if (files.empty()) {
    problems.push_back("the file records no source digests (provenance.sources[].sha256)");
    return nullptr;
  }
  const nlohmann::json* how = nullptr;
  std::vector<bool> matched(files.size(), false);
  for (const FileDigest& d : digests) {
    // A single file is matched to a single recorded file whatever its name
    // now; otherwise by name.
    std::size_t at = files.size();
    if (digests.size() == 1 && paths.size() == 1 && files.size() == 1) at = 0;
    for (std::size_t i = 0; at == files.size() && i < files.size(); ++i)
      if (!matched[i] && file_name((*files[i])["path"].get<std::string>()) == file_name(d.path)) at = i;
    if (at == files.size()) {
      problems.push_back(d.path + ": not among the recorded sources");
      continue;
    }
    matched[at] = true;
    const nlohmann::json& e = *files[at];
    if (!how && e.contains("format")) how = &e;
    if (e["bytes"].get<std::uint64_t>() != d.bytes)
      problems.push_back(d.path + ": " + std::to_string(d.bytes) + " bytes, recorded " +
                         std::to_string(e["bytes"].get<std::uint64_t>()));
    if (e["sha256"].get<std::string>() != d.sha256)
      problems.push_back(d.path + ": sha256 " + d.sha256 + ", recorded " + e["sha256"].get<std::string>());
  }
  // The files of one input (a folder's slices) that the source lacks now.
  if (fs::is_directory(source))
    for (std::size_t i = 0; i < files.size(); ++i)
      if (!matched[i] && (*files[i]).value("format", "") == "tiff")
        problems.push_back((*files[i])["path"].get<std::string>() + ": recorded, missing from " + source);
  return how;
}

std::string voxel_text(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return "(" + std::to_string(x) + "," + std::to_string(y) + "," + std::to_string(z) + ")";
}

// A file re-encoded from an .ivol file (ivol convert IN.ivol OUT.ivol) holds
// its stored values exactly: bit for bit where the value encoding, scale and
// offset are the same, else as the same physical values (NaN for NaN).
void compare_ivol_values(const std::string& source, Reader& reader, AgainstReport& r) {
  Reader input(source);
  const Dims dims = reader.layout().dims;
  if (input.layout().dims != dims) {
    r.source_problems.push_back(source + ": has " + std::to_string(input.layout().dims[0]) + "x" +
                                std::to_string(input.layout().dims[1]) + "x" + std::to_string(input.layout().dims[2]) +
                                " voxels, the file " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                std::to_string(dims[2]));
    return;
  }
  const VolumeLayout &a = input.layout(), &b = reader.layout();
  const bool same_bits = a.encoding == b.encoding && a.value_scale == b.value_scale && a.value_offset == b.value_offset;
  r.values_compared = true;
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  const std::uint32_t slab = static_cast<std::uint32_t>(std::max<std::uint64_t>(1, (16ull << 20) / slice));
  for (std::uint32_t z0 = 0; z0 < dims[2]; z0 += slab) {
    const Box box{{0, 0, z0}, {dims[0], dims[1], std::min(dims[2], z0 + slab)}};
    const std::uint64_t n = box.voxel_count();
    std::vector<bool> equal(n);
    if (same_bits) {
      const std::vector<std::uint8_t> x = input.read_box_bits(box), y = reader.read_box_bits(box);
      const std::size_t width = x.size() / n;
      for (std::uint64_t i = 0; i < n; ++i) equal[i] = std::memcmp(&x[i * width], &y[i * width], width) == 0;
    } else {
      const std::vector<float> x = input.read_box(box), y = reader.read_box(box);
      for (std::uint64_t i = 0; i < n; ++i) equal[i] = x[i] == y[i] || (std::isnan(x[i]) && std::isnan(y[i]));
    }
    r.voxels += n;
    for (std::uint64_t i = 0; i < n; ++i) {
      if (equal[i] || r.differing++ >= 10) continue;
      const auto x = static_cast<std::uint32_t>(i % dims[0]), y = static_cast<std::uint32_t>(i / dims[0] % dims[1]),
                 z = static_cast<std::uint32_t>(z0 + i / slice);
      std::ostringstream text;
      text.precision(9);
      text << voxel_text(x, y, z) << ": source " << input.voxel_value(x, y, z) << ", file "
           << reader.voxel_value(x, y, z) << (same_bits ? " (stored bits differ)" : "");
      r.first_differences.push_back(text.str());
    }
  }
}

void compare_values(const std::string& source, const nlohmann::json& how, Reader& reader, AgainstReport& r) {
  const std::string format = how.value("format", "");
  if (format.empty() || format == "analytic") {
    r.values_skipped = "the recorded source is not a volume";
    return;
  }
  if (format == "ivol") {
    compare_ivol_values(source, reader, r);
    return;
  }
  ForeignOptions foreign;
  const Dims dims = reader.layout().dims;
  foreign.raw.dims = dims;
  foreign.raw_dims_given = true;
  if (!convert::parse_sample_type(how.value("sample_type", "f32"), foreign.raw.type))
    throw Error(ErrorClass::Malformed, "provenance.sources: unknown sample_type");
  foreign.raw.big_endian = how.value("endian", "little") == "big";
  foreign.raw.header_bytes = how.value("header_bytes", std::uint64_t{0});
  foreign.dataset = how.value("dataset", foreign.dataset);
  foreign.grid = how.value("grid", std::string());
  const auto volume = open_source(source, detect_format(source, format, "--against"), foreign);
  const convert::DenseVolume& shape = volume->shape();
  if (shape.dims != dims) {
    r.source_problems.push_back(source + ": has " + std::to_string(shape.dims[0]) + "x" +
                                std::to_string(shape.dims[1]) + "x" + std::to_string(shape.dims[2]) +
                                " voxels, the file " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                std::to_string(dims[2]));
    return;
  }
  const nlohmann::json& built = reader.metadata().structure;
  if (!built.value("lossless", true)) r.tolerance = built.value("max_abs_error", 0.0);
  r.values_compared = true;
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  const std::uint32_t slab = static_cast<std::uint32_t>(std::max<std::uint64_t>(1, (16ull << 20) / slice));
  convert::DenseVolume samples;
  samples.type = shape.type;
  for (std::uint32_t z0 = 0; z0 < dims[2]; z0 += slab) {
    const std::uint32_t n = std::min(slab, dims[2] - z0);
    samples.data.resize(n * slice * convert::sample_size(shape.type));
    volume->read(z0, n, samples.data.data());
    const std::vector<float> stored = reader.read_box({{0, 0, z0}, {dims[0], dims[1], z0 + n}});
    for (std::uint64_t i = 0; i < n * slice; ++i) {
      const double want = static_cast<float>(samples.value(i));
      const double got = stored[i];
      ++r.voxels;
      const bool same = r.tolerance == 0.0 ? (want == got || (std::isnan(want) && std::isnan(got)))
                                           : std::abs(want - got) <= r.tolerance * (1 + 1e-6);
      if (same) continue;
      if (r.differing++ < 10) {
        std::ostringstream text;
        text.precision(9);
        text << voxel_text(static_cast<std::uint32_t>(i % dims[0]), static_cast<std::uint32_t>(i / dims[0] % dims[1]),
                           static_cast<std::uint32_t>(z0 + i / slice))
             << ": source " << want << ", file " << got;
        r.first_differences.push_back(text.str());
      }
    }
  }
}

}  // namespace

nlohmann::json AgainstReport::to_json() const {
  nlohmann::json j = {{"source", source},
                      {"ok", ok()},
                      {"source_problems", source_problems},
                      {"values_compared", values_compared},
                      {"voxels", voxels},
                      {"differing_voxels", differing},
                      {"tolerance", tolerance},
                      {"first_differences", first_differences}};
  if (!values_skipped.empty()) j["values_skipped"] = values_skipped;
  return j;
}

AgainstReport verify_against(const std::string& source, const std::string& file) {
  AgainstReport r;
  r.source = source;
  Reader reader(file);
  const nlohmann::json& provenance = reader.metadata().provenance;
  const nlohmann::json recorded = provenance.contains("sources") && provenance["sources"].is_array()
                                      ? provenance["sources"]
                                      : nlohmann::json::array();
  try {
    const nlohmann::json* how = compare_digests(source, recorded, r.source_problems);
    if (how)
      compare_values(source, *how, reader, r);
    else
      r.values_skipped = "no recorded volume source says how to read " + source;
  } catch (const std::exception& e) {
    r.source_problems.push_back(e.what());
  }
  return r;
}

}  // namespace ivol::cli
