#include "ivol/check.hpp"

#include <algorithm>
#include <cstring>
#include <set>

#include "block_reader.hpp"
#include "file_index.hpp"
#include "ivol/encoding.hpp"
#include "reader_impl.hpp"
#include "stored_levels.hpp"
#include "tree_verify.hpp"

namespace ivol {

namespace {

// Each level of detail a bricked grid stores (spec §8A.5) against the level
// computed from its full-resolution values (§12.3), brick layer by brick
// layer. 16-bit grids: one pass over the volume sums every level as the
// writer does (a different path from the Reader's, which the tests compare
// them with). float32 grids: each stored level against the Reader's own
// sum, a pass per level (a path other than the writer's, too).
void check_stored_levels(const std::string& path, Reader& stored) {
  const VolumeLayout& v = stored.layout();
  std::set<unsigned> levels;
  for (const BlockInfo& b : stored.info().blocks)
    if (b.stream == 7) levels.insert(b.level);
  if (levels.empty()) return;
  const std::uint64_t edge = std::uint64_t{1} << v.cell_log2;
  const std::size_t width = encoding_width(v.encoding);
  auto differ = [&](unsigned k, const Box& layer, const std::uint8_t* want, const std::vector<std::uint8_t>& got) {
    for (std::uint64_t n = 0; n * width < got.size(); ++n)
      if (std::memcmp(want + n * width, got.data() + n * width, width) != 0) {
        const std::uint64_t nx = layer.hi[0] - layer.lo[0], ny = layer.hi[1] - layer.lo[1];
        throw Error(ErrorClass::Malformed, "stored level of detail " + std::to_string(k) + " differs at (" +
                                               std::to_string(layer.lo[0] + n % nx) + ", " +
                                               std::to_string(layer.lo[1] + n / nx % ny) + ", " +
                                               std::to_string(layer.lo[2] + n / nx / ny) +
                                               ") from the level computed from full resolution (spec §8A.5)");
      }
  };
  auto layer_box = [&](const Dims& d, std::uint32_t layer) {
    return Box{{0, 0, static_cast<std::uint32_t>(layer * edge)},
               {d[0], d[1], static_cast<std::uint32_t>(std::min<std::uint64_t>((layer + 1) * edge, d[2]))}};
  };
  if (width == 4) {
    ReaderOptions summed_options;
    summed_options.stored_levels = false;
    Reader summed(path, summed_options);
    for (const unsigned k : levels) {
      const Dims d = lod_dims(v.dims, k);
      for (std::uint32_t layer = 0; std::uint64_t{layer} * edge < d[2]; ++layer) {
        const Box box = layer_box(d, layer);
        differ(k, box, summed.read_box_bits(box, k).data(), stored.read_box_bits(box, k));
      }
    }
    return;
  }
  Reader full(path);
  detail::StoredLevels sums(v.dims, v.cell_log2, v.encoding, *levels.begin());
  for (std::uint32_t z = 0; z < v.dims[2]; z += static_cast<std::uint32_t>(edge)) {
    const std::uint32_t count = static_cast<std::uint32_t>(std::min<std::uint64_t>(edge, v.dims[2] - z));
    const std::vector<std::uint8_t> bytes = full.read_box_bits(Box{{0, 0, z}, {v.dims[0], v.dims[1], z + count}}, 0);
    std::vector<std::uint16_t> values(bytes.size() / 2);
    std::memcpy(values.data(), bytes.data(), bytes.size());
    sums.add(values.data(), z, count,
             [&](unsigned k, const Dims& d, std::uint32_t layer, const std::uint32_t* computed) {
               if (!levels.count(k)) return;
               const Box box = layer_box(d, layer);
               const std::size_t n = std::size_t{d[0]} * d[1] * (box.hi[2] - box.lo[2]);
               std::vector<std::uint16_t> codes(computed, computed + n);
               differ(k, box, reinterpret_cast<const std::uint8_t*>(codes.data()), stored.read_box_bits(box, k));
             });
  }
}

}  // namespace

CheckReport check_file(const std::string& path) {
  CheckReport report;
  auto note = [&](const Error& e) { report.problems.push_back({e.error_class(), e.what()}); };

  // 1. Header, footer and index: without them nothing else can be found.
  std::unique_ptr<detail::RandomAccessFile> file;
  try {
    file = std::make_unique<detail::RandomAccessFile>(path);
    report.info = detail::read_file_structure(*file);
  } catch (const Error& e) {
    note(e);
    return report;
  }

  // 2. Every block on its own, so that one damaged block hides no other.
  const FileInfo& info = *report.info;
  std::string metadata_text;
  for (std::size_t b = 0; b < info.blocks.size(); ++b) {
    const BlockInfo& block = info.blocks[b];
    ++report.blocks_checked;
    try {
      if (!detail::is_known_stream(block.stream, info.layout.kind)) {  // only its CRC means anything
        detail::check_block_crc(*file, block, b);
        continue;
      }
      const auto decoded = detail::read_and_decode_block(
          *file, block, b, detail::stream_width(block.stream, info.layout.encoding),
          detail::is_known_stream(block.stream, info.layout.kind), info.framed(),
          detail::brick_of_block(info.layout, block.stream, block.level, block.first_element));
      if (block.stream == 1) metadata_text.assign(decoded.begin(), decoded.end());
    } catch (const Error& e) {
      ++report.blocks_damaged;
      note(e);
    }
  }
  if (!report.problems.empty()) return report;  // the tree walk would only trip over the same blocks

  // 3. The metadata, then the whole tree: structure and every inner average.
  try {
    Metadata::parse(metadata_text);
  } catch (const Error& e) {
    report.problems.push_back({e.error_class(), path + ": " + e.what()});
    return report;
  }
  try {
    Reader reader(path);  // for the grids of spec §8A, opening checks their structure
    if (reader.layout().kind == StructureKind::Bricked) check_stored_levels(path, reader);
    if (reader.layout().kind != StructureKind::Octree) {
      report.tree_checked = true;
      return report;
    }
    detail::ImplAccess access{reader.impl_.get()};
    detail::TreeVerifier<detail::ImplAccess> verifier(access, reader.layout());
    verifier.run();
    report.tree_checked = true;
  } catch (const Error& e) {
    report.problems.push_back({e.error_class(), path + ": " + e.what()});
  }
  return report;
}

}  // namespace ivol
