// Salvage of format 1.3 files (spec §18): a file cut at any byte yields every
// complete block before the cut, and the rest from the nearest coarser level
// that survived; a damaged block in the middle is skipped and the blocks
// after it are found again. The expected volume is computed here from the
// uncut file's own blocks and the cut position alone; the reference reader
// (written from the spec) salvages every cut too and must agree byte for byte.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <random>

#include "ivol/bricked_writer.hpp"
#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/structures.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

// The uncut file's streams, element by element, with the block each lies in.
struct Streams {
  FileInfo info;
  std::vector<std::uint64_t> nodes;
  std::vector<std::uint32_t> values;
  std::vector<std::size_t> node_block, value_block;  // index into info.blocks
};

Streams load_streams(const std::string& path) {
  Reader reader(path);
  Streams s;
  s.info = reader.info();
  const std::size_t width = encoding_width(s.info.layout.encoding);
  for (std::size_t b = 0; b < s.info.blocks.size(); ++b) {
    const BlockInfo& block = s.info.blocks[b];
    if (block.stream != 2 && block.stream != 3) continue;
    const auto bytes = reader.read_block(b);
    for (std::uint32_t e = 0; e < block.element_count; ++e) {
      const std::uint64_t at = block.first_element + e;
      if (block.stream == 2) {
        if (s.nodes.size() <= at) s.nodes.resize(at + 1), s.node_block.resize(at + 1);
        std::memcpy(&s.nodes[at], bytes.data() + 8 * e, 8);
        s.node_block[at] = b;
      } else {
        if (s.values.size() <= at) s.values.resize(at + 1), s.value_block.resize(at + 1);
        std::uint32_t bits = 0;
        std::memcpy(&bits, bytes.data() + width * e, width);
        s.values[at] = bits;
        s.value_block[at] = b;
      }
    }
  }
  return s;
}

// What a salvaging reader must produce when only the blocks for which
// `survived(block)` holds are there: each voxel the value of its own leaf if
// it survived, else of its nearest ancestor whose value survived (0 for none),
// descending only through nodes whose word survived. `exact` marks voxels
// that got their own leaf's value.
void expected_octree(const Streams& s, const std::function<bool(std::size_t)>& survived,
                     std::vector<std::uint32_t>& bits, std::vector<std::uint8_t>& exact) {
  const VolumeLayout& v = s.info.layout;
  const Dims d = v.dims;
  bits.assign(voxel_count(d), 0);
  exact.assign(bits.size(), 0);
  std::function<void(unsigned, std::uint32_t, std::uint32_t, std::uint32_t, std::uint64_t, std::uint64_t,
                     std::uint32_t)>
      visit = [&](unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, std::uint64_t value,
                  std::uint64_t inner, std::uint32_t fallback) {
        const bool have = survived(s.value_block[value]);
        const std::uint32_t own = have ? s.values[value] : fallback;
        const bool have_word = inner != ~0ull && survived(s.node_block[inner]);
        if (inner == ~0ull || !have_word) {
          const std::uint64_t side = std::uint64_t{1} << (v.depth - level);
          for (std::uint64_t z = k * side; z < std::min<std::uint64_t>((k + 1) * side, d[2]); ++z)
            for (std::uint64_t y = j * side; y < std::min<std::uint64_t>((j + 1) * side, d[1]); ++y)
              for (std::uint64_t x = i * side; x < std::min<std::uint64_t>((i + 1) * side, d[0]); ++x) {
                bits[(z * d[1] + y) * d[0] + x] = own;
                exact[(z * d[1] + y) * d[0] + x] = have && inner == ~0ull;
              }
          return;
        }
        const std::uint64_t word = s.nodes[inner];
        const unsigned mask = static_cast<unsigned>(word >> 56);
        std::uint64_t next = word & ((1ull << 56) - 1);
        for (unsigned c = 0; c < 8; ++c) {
          const std::uint64_t child_inner = (mask >> c) & 1u ? next++ : ~0ull;
          visit(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u), 1 + 8 * inner + c,
                child_inner, own);
        }
      };
  visit(0, 0, 0, 0, 0, v.inner_count[0] ? 0 : ~0ull, 0);
}

// A regular grid: a voxel's value survived or it reads as code 0.
void expected_grid(const Streams& s, const std::function<bool(std::size_t)>& survived, std::vector<std::uint32_t>& bits,
                   std::vector<std::uint8_t>& exact) {
  bits.assign(s.values.size(), 0);
  exact.assign(s.values.size(), 0);
  for (std::size_t i = 0; i < s.values.size(); ++i)
    if (survived(s.value_block[i])) bits[i] = s.values[i], exact[i] = 1;
}

std::vector<std::uint32_t> as_bits(const std::vector<std::uint8_t>& bytes, std::size_t width) {
  std::vector<std::uint32_t> bits(bytes.size() / width, 0);
  for (std::size_t i = 0; i < bits.size(); ++i) std::memcpy(&bits[i], bytes.data() + i * width, width);
  return bits;
}

const std::string kReferenceReader = std::string(IVOL_SOURCE_DIR) + "/format-spec/reference-reader/ivolref.py";

// Salvages the prefix of `path` cut at every byte, with libformat and with
// the reference reader, and checks both against the expected volume.
void check_every_cut(const std::string& path) {
  const Streams s = load_streams(path);
  const VolumeLayout& v = s.info.layout;
  const Dims d = v.dims;
  const std::size_t width = encoding_width(v.encoding);
  const auto file = test::read_bytes(path);
  const std::string cut_path = test::temp_path("cut.ivol");

  // The reference reader: every cut of the file in one run, one record each
  // (a byte 1 when it salvaged, then the dense export's bytes).
  const std::string ref_out = test::temp_path("ref-cuts.bin");
  const auto ref = test::run_command(std::string(IVOL_PYTHON) + " " + kReferenceReader + " salvage " + path +
                                     " --every-cut -o " + ref_out);
  ASSERT_EQ(ref.exit_code, 0) << ref.output;
  const auto ref_bytes = test::read_bytes(ref_out);
  const std::size_t record = 1 + voxel_count(d) * width;
  ASSERT_EQ(ref_bytes.size(), file.size() * record);

  std::size_t salvaged_cuts = 0, with_damage = 0;
  for (std::size_t cut = 0; cut < file.size(); ++cut) {
    SCOPED_TRACE("cut at byte " + std::to_string(cut) + " of " + std::to_string(file.size()));
    test::write_bytes(cut_path, std::vector<std::uint8_t>(file.begin(), file.begin() + cut));
    ReaderOptions options;
    options.salvage = true;
    const bool header_intact = cut >= s.info.header_size;
    std::optional<Reader> reader;
    try {
      reader.emplace(cut_path, options);
    } catch (const Error& e) {
      EXPECT_FALSE(header_intact) << e.what();
      EXPECT_EQ(ref_bytes[cut * record], 0) << "the reference reader salvaged what libformat did not";
      continue;
    }
    ASSERT_TRUE(header_intact) << "salvaged a file whose header is cut";
    ASSERT_TRUE(reader->info().salvage);
    ++salvaged_cuts;
    // Every complete block before the cut is used, and nothing else.
    const auto survived = [&](std::size_t b) {
      return s.info.blocks[b].file_offset + s.info.blocks[b].stored_size <= cut;
    };
    std::size_t complete = 0;
    for (std::size_t b = 0; b < s.info.blocks.size(); ++b) complete += survived(b);
    ASSERT_EQ(reader->info().salvage->blocks_used, complete);
    const bool metadata_survived = s.info.blocks[0].stream == 1 && survived(0);
    EXPECT_EQ(reader->info().salvage->metadata, metadata_survived ? "complete" : "missing");

    std::vector<std::uint32_t> expected;
    std::vector<std::uint8_t> exact;
    if (v.kind == StructureKind::Octree)
      expected_octree(s, survived, expected, exact);
    else
      expected_grid(s, survived, expected, exact);
    std::vector<DamagedRegion> damaged;
    const auto bytes = reader->read_box_bits(full_box(d), 0, &damaged);
    ASSERT_EQ(as_bits(bytes, width), expected);
    // Every voxel that did not get its own value lies in a listed region, and
    // a read that needed nothing missing lists nothing.
    bool any_filled = false;
    for (std::uint32_t z = 0; z < d[2]; ++z)
      for (std::uint32_t y = 0; y < d[1]; ++y)
        for (std::uint32_t x = 0; x < d[0]; ++x) {
          if (exact[(std::size_t{z} * d[1] + y) * d[0] + x]) continue;
          any_filled = true;
          bool listed = false;
          for (const DamagedRegion& r : damaged)
            listed = listed || (r.region.lo[0] <= x && x < r.region.hi[0] && r.region.lo[1] <= y &&
                                y < r.region.hi[1] && r.region.lo[2] <= z && z < r.region.hi[2]);
          ASSERT_TRUE(listed) << "voxel " << x << "," << y << "," << z << " filled but not listed";
        }
    EXPECT_EQ(any_filled, !damaged.empty());
    with_damage += any_filled;
    // The finest complete level of detail is the uncut file's, exactly.
    const int lod = reader->info().salvage->finest_complete_lod;
    if (lod >= 0) {
      Reader uncut(path);
      std::vector<DamagedRegion> none;
      EXPECT_EQ(reader->read_box_bits(full_box(d, lod), lod, &none), uncut.read_box_bits(full_box(d, lod), lod));
      EXPECT_TRUE(none.empty());
    }
    // The reference reader salvaged the same volume.
    ASSERT_EQ(ref_bytes[cut * record], 1) << "the reference reader did not salvage this cut";
    ASSERT_TRUE(std::equal(bytes.begin(), bytes.end(), ref_bytes.begin() + cut * record + 1))
        << "the reference reader salvaged other values";
  }
  EXPECT_EQ(salvaged_cuts, file.size() - s.info.header_size);
  EXPECT_GT(with_damage, salvaged_cuts / 2);
  std::printf("%s: %zu bytes, %zu blocks, %zu cuts salvaged\n", path.c_str(), file.size(), s.info.blocks.size(),
              salvaged_cuts);
}

std::vector<float> smooth_volume(const Dims& d, std::mt19937_64& rng) {
  std::vector<float> volume = test::random_volume(d, rng, 0.05, 3);
  return volume;
}

TEST(Salvage, EveryCutOfAnOctree) {
  const Dims dims{13, 11, 9};
  std::mt19937_64 rng(16);
  const std::vector<float> volume = smooth_volume(dims, rng);
  BuildOptions build;
  build.encoding = ValueEncoding::Float32;
  WriteOptions write;
  write.block_bytes = 96;
  const std::string path = test::temp_path("octree.ivol");
  Metadata m;
  m.voxel_size = {0.5, 0.5, 0.25};
  write_octree(build_octree(volume.data(), dims, build).octree, m, path, write);
  const Streams s = load_streams(path);
  ASSERT_GE(s.info.layout.depth, 4u);
  ASSERT_EQ(s.info.blocks.front().stream, 1) << "the metadata comes first";
  check_every_cut(path);
}

TEST(Salvage, EveryCutOfARegularGrid) {
  NeedMask mask;
  mask.dims = {10, 7, 6};
  mask.factor = 1;
  mask.cells = mask.dims;
  mask.need.assign(voxel_count(mask.dims), 1);
  auto grid = generate_structure(StructureKind::Regular, mask);
  std::vector<float> dense(voxel_count(mask.dims));
  for (std::size_t i = 0; i < dense.size(); ++i) dense[i] = static_cast<float>((i * 37) % 101) * 0.5f;
  grid->sample_dense(dense.data());
  StreamingOptions options;
  options.build.encoding = ValueEncoding::Binary16;
  options.write.block_bytes = 64;
  const std::string path = test::temp_path("regular.ivol");
  write_structure(*grid, path, Metadata{}, options);
  check_every_cut(path);
}

TEST(Salvage, EveryCutOfAStreamedBinary16Octree) {
  const Dims dims{12, 10, 16};
  std::mt19937_64 rng(7);
  const std::vector<float> volume = smooth_volume(dims, rng);
  StreamingOptions options;
  options.build.encoding = ValueEncoding::Binary16;
  options.write.block_bytes = 80;
  options.slab_slices = 4;
  const std::string path = test::temp_path("streamed.ivol");
  StreamingOctreeWriter writer(path, dims, options);
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  while (writer.next_slab_count() > 0) writer.add_slab(volume.data() + writer.next_slab_first() * slice, nullptr);
  writer.finish(Metadata{});
  check_every_cut(path);
}

// A block zeroed in the middle: the scan finds the blocks after it again;
// only what the zeroed block held is filled from above. The footer is cut
// off too, so that the index cannot be used.
TEST(Salvage, ResynchronisesAfterADamagedBlock) {
  const Dims dims{16, 16, 16};
  std::mt19937_64 rng(5);
  const std::vector<float> volume = smooth_volume(dims, rng);
  BuildOptions build;
  build.encoding = ValueEncoding::Binary16;
  WriteOptions write;
  write.block_bytes = 128;
  const std::string path = test::temp_path("whole.ivol");
  write_octree(build_octree(volume.data(), dims, build).octree, Metadata{}, path, write);
  const Streams s = load_streams(path);
  for (const std::uint8_t stream : {std::uint8_t{3}, std::uint8_t{2}}) {
    // The middle block of the deepest level of this stream that has several.
    std::vector<std::size_t> candidates;
    for (std::size_t b = 0; b < s.info.blocks.size(); ++b)
      if (s.info.blocks[b].stream == stream) candidates.push_back(b);
    ASSERT_GE(candidates.size(), 3u);
    const std::size_t victim = candidates[candidates.size() - 2];
    SCOPED_TRACE("zeroed block " + std::to_string(victim) + " (" + stream_name(stream) + ")");
    auto bytes = test::read_bytes(path);
    const BlockInfo& b = s.info.blocks[victim];
    std::fill(bytes.begin() + static_cast<std::ptrdiff_t>(b.file_offset),
              bytes.begin() + static_cast<std::ptrdiff_t>(b.file_offset + b.stored_size), 0);
    bytes.resize(bytes.size() - 10);  // no footer
    const std::string damaged_path = test::temp_path("damaged.ivol");
    test::write_bytes(damaged_path, bytes);
    ReaderOptions options;
    options.salvage = true;
    Reader reader(damaged_path, options);
    const SalvageInfo& info = *reader.info().salvage;
    EXPECT_EQ(info.blocks_found, s.info.blocks.size() - 1);
    EXPECT_EQ(info.bytes_lost, b.stored_size + s.info.index_size + 32 - 10);
    ASSERT_GE(info.gaps.size(), 1u);
    EXPECT_EQ(info.gaps[0], std::make_pair(b.file_offset, b.file_offset + b.stored_size));
    // Every block but the zeroed one is used, except (for a nodes block) the
    // levels below it, whose parents' words are incomplete (spec §18).
    const auto survived = [&](std::size_t n) {
      if (n == victim) return false;
      if (stream == 2) {
        const BlockInfo& other = s.info.blocks[n];
        if (other.stream == 2 && other.level > b.level) return false;
        if (other.stream == 3 && other.level > b.level + 1) return false;
      }
      return true;
    };
    std::size_t used = 0;
    for (std::size_t n = 0; n < s.info.blocks.size(); ++n) used += survived(n);
    EXPECT_EQ(info.blocks_used, used);
    std::vector<std::uint32_t> expected;
    std::vector<std::uint8_t> exact;
    expected_octree(s, survived, expected, exact);
    std::vector<DamagedRegion> damaged;
    EXPECT_EQ(as_bits(reader.read_box_bits(full_box(dims), 0, &damaged), 2), expected);
    EXPECT_FALSE(damaged.empty());
    EXPECT_FALSE(check_file(damaged_path).ok());
  }
}

// Files without framing (format 1.2) cannot be salvaged, and say so.
TEST(Salvage, UnframedFilesSayWhyNot) {
  const Dims dims{8, 8, 8};
  std::mt19937_64 rng(1);
  const std::vector<float> volume = smooth_volume(dims, rng);
  WriteOptions write;
  write.framed_blocks = false;
  const std::string path = test::temp_path("v12.ivol");
  write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, Metadata{}, path, write);
  EXPECT_EQ(Reader(path).info().version_minor, 2);
  EXPECT_EQ(Reader(path).info().header_size, 40u);
  auto bytes = test::read_bytes(path);
  bytes.resize(bytes.size() / 2);
  test::write_bytes(path, bytes);
  ReaderOptions options;
  options.salvage = true;
  try {
    Reader reader(path, options);
    ADD_FAILURE() << "salvaged an unframed file";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::Truncated);
    EXPECT_NE(std::string(e.what()).find("not framed"), std::string::npos) << e.what();
  }
}

}  // namespace

namespace {

// The first `size` bytes of the file at `from`, as a file of its own,
// opened salvaging.
Reader salvage_prefix(const std::string& from, std::size_t size, const std::string& name) {
  auto bytes = test::read_bytes(from);
  bytes.resize(size);
  const std::string path = test::temp_path(name);
  test::write_bytes(path, bytes);
  ReaderOptions options;
  options.salvage = true;
  return Reader(path, options);
}

// A file whose final metadata comes last, after an early metadata block
// (stream 6, spec §15): cut before the final one, salvage uses the early
// one and says so; uncut, a reader uses stream 1 and skips stream 6.
TEST(Salvage, FallsBackToTheEarlyMetadata) {
  const std::string vector =
      std::string(IVOL_SOURCE_DIR) + "/format-spec/vectors/valid/framed_octree_6x6x6_float32_early_metadata.ivol";
  Reader whole(vector);
  const FileInfo& info = whole.info();
  ASSERT_EQ(info.blocks.front().stream, 6);
  ASSERT_EQ(info.blocks.back().stream, 1);
  EXPECT_EQ(whole.metadata().voxel_size[0], 0.05);
  Reader cut = salvage_prefix(vector, info.blocks.back().file_offset, "early.ivol");
  EXPECT_EQ(cut.info().salvage->metadata, "early");
  EXPECT_EQ(cut.metadata().voxel_size[0], 0.1);
  EXPECT_EQ(cut.info().salvage->finest_complete_lod, 0);
  std::vector<DamagedRegion> damaged;
  EXPECT_EQ(cut.read_box_bits(full_box(info.layout.dims), 0, &damaged),
            whole.read_box_bits(full_box(info.layout.dims)));
  EXPECT_TRUE(damaged.empty());
}

// A bricked grid learns its final metadata after the values (the sources'
// digests, what rounding lost), so it writes the metadata block last; the
// early metadata before the first value keeps voxel size, origin and unit
// in a file cut anywhere after it (spec §15). A bricked file cut in half
// lost them before.
TEST(Salvage, ABrickedGridWritesItsEarlyMetadataFirst) {
  const Dims dims{40, 36, 70};
  std::vector<std::uint32_t> values(std::size_t{dims[0]} * dims[1] * dims[2]);
  std::mt19937 rng(17);
  for (auto& v : values) {
    const float f = std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
    std::memcpy(&v, &f, 4);
  }
  const std::string path = test::temp_path("bricked-early.ivol");
  BrickedOptions options;
  options.encoding = ValueEncoding::Float32;
  options.brick_log2 = 3;
  {
    BrickedGridWriter writer(path, dims, options);
    Metadata early;
    early.voxel_size = {0.05, 0.05, 0.2};
    early.origin = {1.0, 2.0, 3.0};
    early.unit = "mm";
    writer.write_early_metadata(early);
    const std::size_t slice = std::size_t{dims[0]} * dims[1];
    for (std::uint32_t z; (z = writer.next_layer_first()), writer.next_layer_count() != 0;)
      writer.add_layer(values.data() + z * slice);
    EXPECT_THROW(writer.write_early_metadata(early), Error);  // after the first layer
    Metadata final_metadata = early;
    final_metadata.provenance["sources"] = nlohmann::json::array({{{"sha256", "00"}}});
    writer.finish(final_metadata);
  }
  Reader whole(path);
  const FileInfo& info = whole.info();
  ASSERT_EQ(info.blocks.front().stream, 6);
  EXPECT_EQ(info.blocks.front().flags, 1);  // ignorable
  EXPECT_EQ(info.blocks.back().stream, 1);
  EXPECT_TRUE(whole.metadata().provenance.contains("sources"));  // the final metadata, not the early one
  EXPECT_TRUE(check_file(path).ok());
  Reader cut = salvage_prefix(path, test::read_bytes(path).size() / 2, "bricked-early-cut.ivol");
  EXPECT_EQ(cut.info().salvage->metadata, "early");
  EXPECT_EQ(cut.metadata().voxel_size[2], 0.2);
  EXPECT_EQ(cut.metadata().origin[1], 2.0);
  EXPECT_EQ(cut.metadata().unit, "mm");
  EXPECT_FALSE(cut.metadata().provenance.contains("sources"));
}

}  // namespace
