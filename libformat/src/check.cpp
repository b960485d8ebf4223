#include "ivol/check.hpp"

#include "block_reader.hpp"
#include "file_index.hpp"
#include "reader_impl.hpp"
#include "tree_verify.hpp"

namespace ivol {

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
      const auto decoded =
          detail::read_and_decode_block(*file, block, b, detail::stream_width(block.stream, info.layout.encoding),
                                        detail::is_known_stream(block.stream, info.layout.kind), info.framed(),
                                        detail::brick_of_block(info.layout, block.stream, block.first_element));
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
