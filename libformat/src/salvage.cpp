// Salvage (spec §18): the blocks of a framed file found by their headers
// alone, and the index they imply.
#include "salvage.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

#include "block_reader.hpp"
#include "brick_grid.hpp"
#include "file_index.hpp"
#include "framing.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/metadata.hpp"
#include "layout.hpp"

namespace ivol::detail {
namespace {

constexpr std::size_t kMaxListed = 100;
// A header claiming more than this is taken for a false signature: no block
// of a known stream is near it (64 MiB decoded, and zstd's worst case).
constexpr std::uint32_t kMaxPayload = 128u << 20;
constexpr std::size_t kSearchWindow = 1u << 20;

class Salvager {
 public:
  Salvager(RandomAccessFile& file, const std::string& reason) : file_(file) {
    salvage_ = std::make_shared<SalvageInfo>();
    salvage_->reason = reason;
  }

  SalvagedFile run() {
    read_header();
    scan();
    rebuild();
    result_.info.salvage = salvage_;
    return std::move(result_);
  }

 private:
  [[noreturn]] void fail(ErrorClass c, const std::string& what) const { throw Error(c, what); }

  void note(const std::string& what) {
    if (salvage_->notes.size() < kMaxListed) salvage_->notes.push_back(what);
  }

  static std::string describe(const BlockInfo& b) {
    return "block at offset " + std::to_string(b.file_offset) + " (" + stream_name(b.stream) + ", level " +
           std::to_string(b.level) + ", elements " + std::to_string(b.first_element) + " .. " +
           std::to_string(b.first_element + b.element_count) + ")";
  }

  // Spec §18 step 1: the header, with the volume descriptor, must be intact.
  void read_header() {
    FileInfo& info = result_.info;
    info.file_size = file_.size();
    if (info.file_size < 16) fail(ErrorClass::Truncated, "the file ends inside its header");
    const auto start = file_.read(0, 16);
    if (std::memcmp(start.data(), layout::kSignature.data(), 8) != 0)
      fail(ErrorClass::NotIvol, "the file does not start with the .ivol signature");
    info.version_major = layout::load<std::uint16_t>(&start[layout::kHeaderVersionMajor]);
    if (info.version_major != layout::kVersionMajor)
      fail(ErrorClass::UnsupportedVersion, "format version " + std::to_string(info.version_major) + ".x");
    info.version_minor = layout::load<std::uint16_t>(&start[layout::kHeaderVersionMinor]);
    info.header_size = layout::load<std::uint32_t>(&start[layout::kHeaderSizeField]);
    if (info.header_size < layout::kHeaderSize || info.header_size > layout::kMaxHeaderSize)
      fail(ErrorClass::Malformed, "header_size " + std::to_string(info.header_size) + " is outside 40 .. 4096");
    if (info.file_size < info.header_size) fail(ErrorClass::Truncated, "the file ends inside its header");
    const auto header = file_.read(0, info.header_size);
    if (layout::load<std::uint32_t>(&header[info.header_size - 4]) != crc32c(header.data(), info.header_size - 4))
      fail(ErrorClass::Checksum, "the header's CRC-32C does not match");
    info.required_features = layout::load<std::uint64_t>(&header[layout::kHeaderRequiredFeatures]);
    info.optional_features = layout::load<std::uint64_t>(&header[layout::kHeaderOptionalFeatures]);
    if (!info.framed())
      fail(ErrorClass::UnsupportedFeature,
           "the file is not framed (format 1.3, required feature bit 0): its blocks cannot be found without the index");
    if (info.required_features & ~layout::kFeatureFramedBlocks)
      fail(ErrorClass::UnsupportedFeature, "the file needs required features this reader does not know");
    if (info.header_size < layout::kFramedHeaderSize)
      fail(ErrorClass::Malformed, "header_size is below 80: no volume descriptor");
    const unsigned char* d = &header[layout::kHeaderDescriptor - 8];  // index fixed-part offsets apply
    VolumeLayout& v = info.layout;
    const std::uint8_t kind = d[layout::kIndexStructureKind];
    const std::uint8_t encoding = d[layout::kIndexValueEncoding];
    if (kind < 1 || kind > 5) fail(ErrorClass::UnsupportedFeature, "structure_kind " + std::to_string(kind));
    if (!is_known_encoding(encoding))
      fail(ErrorClass::UnsupportedFeature, "value_encoding " + std::to_string(encoding));
    v.kind = static_cast<StructureKind>(kind);
    v.encoding = static_cast<ValueEncoding>(encoding);
    v.depth = d[layout::kIndexDepth];
    v.cell_log2 = d[layout::kIndexCellLog2];
    for (int a = 0; a < 3; ++a) {
      v.dims[a] = layout::load<std::uint32_t>(d + layout::kIndexSizeX + 4 * a);
      if (v.dims[a] == 0) fail(ErrorClass::Malformed, "the volume descriptor's size is 0");
    }
    if (v.depth > layout::kMaxDepth || v.depth != depth_for(v.dims))
      fail(ErrorClass::Malformed, "the volume descriptor's depth does not fit its size");
    if (v.kind == StructureKind::Nested    ? (v.cell_log2 < 1 || v.cell_log2 > 31)
        : v.kind == StructureKind::Bricked ? (v.cell_log2 < 1 || v.cell_log2 > layout::kMaxBrickLog2)
                                           : v.cell_log2 != 0)
      fail(ErrorClass::Malformed, "the volume descriptor's cell_log2 is out of range");
    v.value_scale = layout::load<double>(d + layout::kIndexScale);
    v.value_offset = layout::load<double>(d + layout::kIndexOffset);
    if (!std::isfinite(v.value_scale) || v.value_scale == 0.0 || !std::isfinite(v.value_offset))
      fail(ErrorClass::Malformed, "the volume descriptor's value_scale or value_offset is not finite");
  }

  // The next `IVBK` at or after `from`, or the end of the file.
  std::uint64_t next_signature(std::uint64_t from) {
    const std::uint64_t end = file_.size();
    while (from + 4 <= end) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(kSearchWindow, end - from));
      const auto window = file_.read(from, n);
      for (std::size_t i = 0; i + 4 <= n; ++i)
        if (window[i] == 'I' && std::memcmp(&window[i], layout::kBlockSignature.data(), 4) == 0) return from + i;
      if (from + n >= end) break;
      from += n - 3;  // a signature may straddle two windows
    }
    return end;
  }

  void lost(std::uint64_t begin, std::uint64_t end) {
    if (begin >= end) return;
    salvage_->bytes_lost += end - begin;
    if (salvage_->gaps.size() < kMaxListed) salvage_->gaps.emplace_back(begin, end);
  }

  // Spec §18 step 2: a block whose header and payload CRCs hold is taken and
  // the next one starts after it; elsewhere, search for the next one.
  void scan() {
    const std::uint64_t end = file_.size();
    std::uint64_t pos = result_.info.header_size;
    std::uint64_t gap = pos;
    while (pos < end) {
      if (end - pos > layout::kBlockHeaderSize) {
        const auto header = file_.read(pos, layout::kBlockHeaderSize);
        BlockHeader parsed;
        if (parse_block_header(header.data(), parsed) && parsed.payload_size > 0 &&
            parsed.payload_size <= kMaxPayload && parsed.payload_size <= end - pos - layout::kBlockHeaderSize) {
          const auto payload = file_.read(pos + layout::kBlockHeaderSize, parsed.payload_size);
          if (crc32c(payload.data(), payload.size()) == parsed.payload_crc) {
            lost(gap, pos);
            BlockInfo b = parsed.entry;
            b.file_offset = pos;
            b.stored_size = layout::kBlockHeaderSize + parsed.payload_size;
            b.crc = crc32c_extend(crc32c(header.data(), header.size()), payload.data(), payload.size());
            found_.push_back(b);
            pos += b.stored_size;
            gap = pos;
            continue;
          }
        }
      }
      pos = next_signature(pos + 1);
    }
    lost(gap, end);
    salvage_->blocks_found = found_.size();
  }

  // The metadata: stream 1 when it survived, else the early metadata of
  // stream 6 (spec §15).
  void find_metadata() {
    for (const std::uint8_t stream : {std::uint8_t{1}, layout::kStreamEarlyMetadata}) {
      for (const BlockInfo& b : found_) {
        if (b.stream != stream) continue;
        try {
          if (b.element_count > layout::kMaxMetadataBytes) throw Error(ErrorClass::Malformed, "over 16 MiB");
          const auto bytes = read_and_decode_block(file_, b, 0, 1, true, true);
          std::string text(bytes.begin(), bytes.end());
          Metadata::parse(text);
          result_.metadata_text = std::move(text);
          salvage_->metadata = stream == 1 ? "complete" : "early";
          if (stream == 1) used_.push_back(b);
          return;
        } catch (const Error& e) {
          note(describe(b) + ": not used: " + e.what());
        }
      }
    }
  }

  // Known stream, and fields an index entry could have had (spec §6.3, §6.4, §7).
  bool plausible(const BlockInfo& b) {
    const VolumeLayout& v = result_.info.layout;
    std::string why;
    const std::uint64_t width = stream_width(b.stream, v.encoding);
    // Codecs 3 and 4 only on a bricked grid's values, one brick per block (spec §7, §8A.4).
    const bool brick_codec = (b.codec == 3 || b.codec == 4) && brick_of_block(v, b.stream, b.level, b.first_element) &&
                             v.encoding != ValueEncoding::Float32;
    // Codec 6, the top byte in context, on a bricked grid's bricks of 2 or 4 bytes (spec §7.4).
    const bool top_byte =
        b.codec == 6 && (width == 2 || width == 4) && brick_of_block(v, b.stream, b.level, b.first_element);
    // Codec 5, a zstd frame a byte plane, on any stream of elements wider than a byte (spec §7).
    const bool plane_frames = b.codec == 5 && width >= 2;
    if (b.flags != 0 || (b.codec > 2 && !brick_codec && !plane_frames && !top_byte) || b.element_count == 0)
      why = "flags, codec or element_count out of range";
    else if (b.element_count * width > layout::kMaxBlockDecodedBytes)
      why = "decoded size over 64 MiB";
    else if (b.codec == 0 && b.stored_size != b.element_count * width + layout::kBlockHeaderSize)
      why = "a stored block of the wrong size";
    else if (b.level > v.depth || (v.kind != StructureKind::Octree && b.level != 0))
      why = "level out of range";
    if (why.empty()) return true;
    note(describe(b) + ": not used: " + why);
    return false;
  }

  // Blocks of one stream by first_element; a block overlapping one before it
  // is dropped (a false signature, or a file written twice over).
  std::vector<BlockInfo> stream_blocks(std::uint8_t stream) {
    std::vector<BlockInfo> list;
    for (const BlockInfo& b : found_)
      if (b.stream == stream && plausible(b)) list.push_back(b);
    std::stable_sort(list.begin(), list.end(),
                     [](const BlockInfo& a, const BlockInfo& b) { return a.first_element < b.first_element; });
    std::vector<BlockInfo> kept;
    for (const BlockInfo& b : list) {
      if (!kept.empty() && b.first_element < kept.back().first_element + kept.back().element_count) {
        note(describe(b) + ": not used: it overlaps the " + describe(kept.back()));
        continue;
      }
      kept.push_back(b);
    }
    return kept;
  }

  // Blocks of `list` with the given level lying in [lo, hi), and how many
  // elements they hold.
  std::vector<BlockInfo> in_range(const std::vector<BlockInfo>& list, unsigned level, std::uint64_t lo,
                                  std::uint64_t hi, std::uint64_t& held) {
    std::vector<BlockInfo> out;
    held = 0;
    for (const BlockInfo& b : list) {
      if (b.level != level) continue;
      if (b.first_element < lo || b.first_element > hi || b.element_count > hi - b.first_element) {
        note(describe(b) + ": not used: outside level " + std::to_string(level) + "'s elements");
        continue;
      }
      out.push_back(b);
      held += b.element_count;
    }
    return out;
  }

  // Spec §18 step 3 for the octree: inner_count[l + 1] from the masks of
  // level l while every node of level l was found. Past the last level so
  // known, the next level's count is bounded by 8 × inner_count[l] (so that
  // the children of the nodes found pass the range checks of §8.3) and its
  // values are used; deeper levels are absent.
  void rebuild_octree() {
    VolumeLayout& v = result_.info.layout;
    const std::vector<BlockInfo> nodes = stream_blocks(2);
    const std::vector<BlockInfo> values = stream_blocks(3);
    v.inner_count.assign(v.depth + 1, 0);
    v.inner_count[0] = v.depth > 0 ? 1 : 0;  // a leaf root has no nodes: salvage cannot tell, and lists it
    unsigned known = 0;                      // inner_count[0 .. known] are exact
    std::vector<bool> nodes_complete(v.depth + 1, false);
    for (unsigned l = 0; l < v.depth; ++l) {
      std::uint64_t held = 0;
      const std::uint64_t lo = v.first_inner(l);
      const auto level_nodes = in_range(nodes, l, lo, lo + v.inner_count[l], held);
      std::uint64_t children = 0;
      bool complete = held == v.inner_count[l];
      for (const BlockInfo& b : level_nodes) {
        used_.push_back(b);
        if (!complete) continue;
        try {
          const auto words = read_and_decode_block(file_, b, 0, 8, true, true);
          for (std::size_t w = 0; w < b.element_count; ++w)
            children += static_cast<unsigned>(__builtin_popcount(words[w * 8 + 7]));  // child_mask: the top byte
        } catch (const Error& e) {
          note(describe(b) + ": not used: " + e.what());
          used_.pop_back();
          complete = false;
        }
      }
      nodes_complete[l] = complete;
      if (!complete) {
        if (l + 1 < v.depth) v.inner_count[l + 1] = 8 * v.inner_count[l];
        break;
      }
      v.inner_count[l + 1] = l + 1 == v.depth ? 0 : children;
      known = l + 1;
    }
    if (v.depth == 0) nodes_complete[0] = true;
    // Values: levels 0 .. known + 1 have known ranges (they need the counts of
    // the levels above them only).
    std::vector<bool> values_complete(v.depth + 1, false);
    for (unsigned l = 0; l <= std::min(known + 1, v.depth); ++l) {
      std::uint64_t held = 0;
      const auto level_values = in_range(values, l, v.first_value(l), v.first_value(l) + v.level_values(l), held);
      used_.insert(used_.end(), level_values.begin(), level_values.end());
      salvage_->values_found += held;
      values_complete[l] = held == v.level_values(l);
    }
    for (const BlockInfo& b : values)
      if (b.level > known + 1) note(describe(b) + ": not used: the node words of the level above are missing");
    for (const BlockInfo& b : nodes)
      if (b.level > known) note(describe(b) + ": not used: the node words of the level above are missing");
    if (known == v.depth) salvage_->values_total = v.total_values();
    // The finest level of detail D - l: values of levels 0 .. l and nodes of
    // levels 0 .. l - 1 all found.
    for (unsigned l = 0; l <= v.depth && values_complete[l]; ++l) {
      salvage_->finest_complete_lod = static_cast<int>(v.depth - l);
      if (l < v.depth && !nodes_complete[l]) break;
    }
  }

  // Spec §18 step 3 for the grids of §8A: borders and cell words from the
  // start of their stream, values wherever they lie.
  void rebuild_grid() {
    VolumeLayout& v = result_.info.layout;
    v.inner_count.assign(v.depth + 1, 0);
    for (const std::uint8_t stream : {std::uint8_t{4}, std::uint8_t{5}}) {
      if (!is_known_stream(stream, v.kind)) continue;
      std::uint64_t next = 0;
      for (const BlockInfo& b : stream_blocks(stream)) {
        if (b.first_element != next) {
          note(describe(b) + ": not used: the " + stream_name(stream) + " before it are missing");
          continue;
        }
        used_.push_back(b);
        next += b.element_count;
      }
      // Without every cell word no value can be placed (the borders are
      // checked when the grid is built from them).
      if (stream == 5) {
        const std::uint64_t edge = std::uint64_t{1} << v.cell_log2;
        std::uint64_t cells = 1;
        for (int a = 0; a < 3; ++a) cells *= (v.dims[a] + edge - 1) / edge;
        if (next != cells)
          fail(ErrorClass::Truncated, "only " + std::to_string(next) + " of the nested grid's " +
                                          std::to_string(cells) + " cell words survived: its values cannot be placed");
      }
    }
    std::uint64_t total = ~std::uint64_t{0};  // unknown until the borders or cells are read
    if (v.kind == StructureKind::Regular || v.kind == StructureKind::Bricked) {
      __extension__ using Wide = unsigned __int128;
      const Wide voxels = static_cast<Wide>(v.dims[0]) * v.dims[1] * v.dims[2];
      if (voxels <= (std::uint64_t{1} << 56)) total = static_cast<std::uint64_t>(voxels);
    }
    for (const BlockInfo& b : stream_blocks(3)) {
      if (b.first_element > total || b.element_count > total - b.first_element) {
        note(describe(b) + ": not used: beyond the grid's values");
        continue;
      }
      used_.push_back(b);
      salvage_->values_found += b.element_count;
    }
    if (v.kind == StructureKind::Regular || v.kind == StructureKind::Bricked) {
      salvage_->values_total = total;
      if (salvage_->values_found == total) salvage_->finest_complete_lod = 0;
    }
  }

  void rebuild() {
    find_metadata();
    if (result_.info.layout.kind == StructureKind::Octree)
      rebuild_octree();
    else
      rebuild_grid();
    std::sort(used_.begin(), used_.end(),
              [](const BlockInfo& a, const BlockInfo& b) { return a.file_offset < b.file_offset; });
    result_.info.blocks = std::move(used_);
    salvage_->blocks_used = result_.info.blocks.size();
  }

  RandomAccessFile& file_;
  SalvagedFile result_;
  std::shared_ptr<SalvageInfo> salvage_;
  std::vector<BlockInfo> found_;
  std::vector<BlockInfo> used_;
};

}  // namespace

SalvagedFile salvage_file(RandomAccessFile& file, const std::string& reason) { return Salvager(file, reason).run(); }

}  // namespace ivol::detail

namespace ivol::detail {

FileInfo read_or_salvage(RandomAccessFile& file, bool salvage, std::string& metadata_text) {
  try {
    return read_file_structure(file);
  } catch (const Error& e) {
    if (!salvage) throw;
    SalvagedFile salvaged;
    try {
      salvaged = salvage_file(file, e.what());
    } catch (const Error& why) {
      throw Error(e.error_class(), std::string(e.what()) + "; nothing can be salvaged: " + why.what());
    }
    metadata_text = std::move(salvaged.metadata_text);
    return std::move(salvaged.info);
  }
}

}  // namespace ivol::detail
