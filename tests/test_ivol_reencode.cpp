// ivol → ivol re-encoding (tools/convert/ivol_source.hpp, `ivol convert
// IN.ivol OUT.ivol`): every voxel's stored bits against the arrays the inputs
// were built from, the value encoding with its scale and offset, the
// metadata that carries over, coarse leaves that stay leaves, and the
// refusals where stored values cannot be taken as physical ones.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>

#include "ivol/binary16.hpp"
#include "ivol/build.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "ivol_io.hpp"
#include "ivol_source.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;
using namespace ivol::convert;

const Dims kDims{37, 29, 23};  // odd sides: partial bricks and octree padding

// uint16 codes: a smooth part, noise, a block of one value, both extremes.
std::vector<std::uint16_t> make_codes() {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> noise(-40, 40);
  std::vector<std::uint16_t> v(voxel_count(kDims));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < kDims[2]; ++z)
    for (std::uint32_t y = 0; y < kDims[1]; ++y)
      for (std::uint32_t x = 0; x < kDims[0]; ++x, ++i) {
        const int smooth = 20000 + 300 * static_cast<int>(x) - 200 * static_cast<int>(y) + 50 * static_cast<int>(z);
        v[i] = x < 8 && y < 8 ? 1234 : static_cast<std::uint16_t>(std::clamp(smooth + noise(rng), 0, 65535));
      }
  v[5] = 0;
  v[v.size() - 3] = 65535;
  return v;
}

// binary16 values: a sphere in air, with every special pattern sprinkled in
// (-0, NaNs with payloads, signalling ones, infinities, subnormals).
std::vector<float> make_binary16_values(std::vector<std::uint16_t>& bits) {
  std::mt19937 rng(11);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  bits.resize(voxel_count(kDims));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < kDims[2]; ++z)
    for (std::uint32_t y = 0; y < kDims[1]; ++y)
      for (std::uint32_t x = 0; x < kDims[0]; ++x, ++i) {
        const double r = std::hypot(x - 18.0, y - 14.0, z - 11.0);
        bits[i] = float_to_binary16(r < 8 ? 0.05f + noise(rng) : 0.0f);
      }
  const std::uint16_t special[] = {0x8000, 0x7E01, 0xFD00, 0x7C00, 0xFC00, 0x0001, 0x8001, 0x7C01};
  for (std::size_t k = 400; k < bits.size(); k += 397) bits[k] = special[(k / 397) % 8];
  std::vector<float> values(bits.size());
  for (std::size_t k = 0; k < bits.size(); ++k) values[k] = binary16_to_float(bits[k]);
  return values;
}

template <class Source>
std::string write_octree_file(const std::string& name, const Source* data, const BuildOptions& build,
                              const Metadata& metadata) {
  std::string path = test::temp_path(name);
  write_octree(build_octree(data, kDims, build).octree, metadata, path);
  return path;
}

// What `ivol convert IN.ivol OUT.ivol` does, with the structure asked for.
ImportReport reencode(const std::string& in, const std::string& out, StructureChoice structure = StructureChoice::Auto,
                      const std::function<void(ImportOptions&)>& adjust = {}) {
  IvolSourceInfo info;
  const auto source = open_ivol_stored_slabs(in, 0, &info);
  ImportOptions options;
  options.structure = structure;
  options.brick_log2 = 3;
  options.check_disk_space = false;
  set_reencoding(options, info);
  if (adjust) adjust(options);
  return import_to_ivol(*source, out, options);
}

std::vector<std::uint16_t> bits16(Reader& r) {
  const auto bytes = r.read_box_bits(Box{{0, 0, 0}, kDims});
  std::vector<std::uint16_t> out(bytes.size() / 2);
  std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

std::uint64_t leaf_count(Reader& r) {
  std::uint64_t leaves = 0;
  r.visit_leaves(Box{{0, 0, 0}, kDims}, 0, [&](const Box&, double) { ++leaves; });
  return leaves;
}

TEST(IvolReencode, ScaledUint16CodesKeepTheirScaleOffsetAndMetadata) {
  const std::vector<std::uint16_t> codes = make_codes();
  BuildOptions build;
  build.encoding = ValueEncoding::UInt16;
  build.value_scale = 0.001;
  build.value_offset = -3.5;
  Metadata metadata;
  metadata.voxel_size = {0.1, 0.2, 0.3};
  metadata.unit = "mm";
  metadata.origin = {1.0, -2.0, 3.0};
  metadata.quantity = "linear_attenuation";
  metadata.value_unit = "1/mm";
  metadata.user = {{"scanner", "XT 225"}, {"batch", 42}};
  metadata.structure = {{"kind", "octree"}, {"lossless", true}, {"source_encoding", "f32"}};
  metadata.provenance = {{"command", "made by the test"}};
  const std::string in = write_octree_file("reencode-u16.ivol", codes.data(), build, metadata);

  for (StructureChoice structure : {StructureChoice::Auto, StructureChoice::Octree}) {
    const std::string out = test::temp_path("reencode-u16-out.ivol");
    const ImportReport report = reencode(in, out, structure);
    EXPECT_EQ(report.structure, structure == StructureChoice::Auto ? "bricked" : "octree");
    EXPECT_TRUE(report.lossless);
    Reader r(out);
    EXPECT_EQ(r.layout().encoding, ValueEncoding::UInt16);
    EXPECT_EQ(r.layout().value_scale, 0.001);
    EXPECT_EQ(r.layout().value_offset, -3.5);
    EXPECT_EQ(bits16(r), codes) << "every code as it was";
    const Metadata& m = r.metadata();
    EXPECT_EQ(m.voxel_size, metadata.voxel_size);
    EXPECT_EQ(m.origin, metadata.origin);
    EXPECT_EQ(m.quantity, "linear_attenuation");
    EXPECT_EQ(m.value_unit, "1/mm");
    EXPECT_EQ(m.user, metadata.user);
    EXPECT_EQ(m.structure.value("source_encoding", ""), "f32") << "the input's source type carries over";
    EXPECT_EQ(m.provenance.at("derived_from"), metadata.provenance);
  }
}

TEST(IvolReencode, ScaledValuesAreNotTakenAsPhysical) {
  const std::vector<std::uint16_t> codes = make_codes();
  BuildOptions build;
  build.encoding = ValueEncoding::UInt16;
  build.value_scale = 0.25;
  const std::string in = write_octree_file("reencode-scaled.ivol", codes.data(), build, Metadata{});
  const std::string out = test::temp_path("reencode-scaled-out.ivol");
  // A threshold or another encoding would read the codes as values.
  EXPECT_THROW(reencode(in, out, StructureChoice::Auto,
                        [](ImportOptions& o) {
                          o.keep = KeepRule{false, 100, 1};
                        }),
               Error);
  EXPECT_THROW(reencode(in, out, StructureChoice::Auto, [](ImportOptions& o) { o.encoding = ValueEncoding::Float32; }),
               Error);
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(IvolReencode, Binary16SpecialsBitForBitBothWays) {
  std::vector<std::uint16_t> bits;
  const std::vector<float> values = make_binary16_values(bits);
  BuildOptions build;  // binary16, lossless
  const std::string octree = write_octree_file("reencode-f16.ivol", values.data(), build, Metadata{});
  {
    Reader r(octree);
    ASSERT_EQ(bits16(r), bits) << "the input itself";
  }
  const std::string bricked = test::temp_path("reencode-f16-bricked.ivol");
  EXPECT_EQ(reencode(octree, bricked).structure, "bricked") << "every voxel kept: a bricked grid";
  Reader b(bricked);
  EXPECT_EQ(bits16(b), bits);
  const std::string back = test::temp_path("reencode-f16-back.ivol");
  EXPECT_EQ(reencode(bricked, back, StructureChoice::Octree).structure, "octree");
  Reader o(back);
  EXPECT_EQ(bits16(o), bits);
  Reader original(octree);
  EXPECT_EQ(leaf_count(o), leaf_count(original)) << "equal leaves merge as they did";
}

TEST(IvolReencode, CoarseLeavesStayLeaves) {
  std::vector<std::uint16_t> bits;
  const std::vector<float> values = make_binary16_values(bits);
  std::vector<std::uint8_t> keep(values.size(), 0);
  for (std::size_t i = 0; i < values.size(); ++i) keep[i] = std::fabs(values[i]) > 0.01f;
  BuildOptions build;
  build.keep_mask = keep.data();
  Metadata metadata;
  metadata.structure = {{"kind", "octree"},
                        {"lossless", false},
                        {"max_abs_error", 0.5},
                        {"keep", {{"rule", "threshold"}, {"threshold", 0.01}, {"margin", 0}}}};
  const std::string in = write_octree_file("reencode-object.ivol", values.data(), build, metadata);
  const std::string out = test::temp_path("reencode-object-out.ivol");
  const ImportReport report = reencode(in, out);
  EXPECT_EQ(report.structure, "octree") << report.structure_reason;
  Reader original(in), copy(out);
  EXPECT_EQ(bits16(copy), bits16(original));
  EXPECT_EQ(leaf_count(copy), leaf_count(original)) << "each coarse leaf one leaf again";
  const std::vector<std::uint16_t> kept = bits16(copy);
  for (std::size_t i = 0; i < kept.size(); ++i)
    if (keep[i]) ASSERT_EQ(kept[i], bits[i]) << "kept voxel " << i;
  const nlohmann::json& s = copy.metadata().structure;
  EXPECT_EQ(s.value("lossless", true), false) << "as far from the scan as the input";
  EXPECT_EQ(s.value("max_abs_error", 0.0), 0.5);
  EXPECT_EQ(s.at("keep"), metadata.structure.at("keep"));
  // Asked for, a bricked grid holds the same voxels.
  const std::string grid = test::temp_path("reencode-object-grid.ivol");
  EXPECT_EQ(reencode(in, grid, StructureChoice::Bricked).structure, "bricked");
  Reader g(grid);
  EXPECT_EQ(bits16(g), bits16(original));
}

}  // namespace
