// The independent reference reader (format-spec/reference-reader, written
// from the spec alone) and libformat agree: on every conformance vector, and
// on files libformat writes at random (sizes, encodings, masks, codecs, block
// sizes), bit for bit.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <set>

#include "ivol/binary16.hpp"
#include "ivol/bricked_writer.hpp"
#include "ivol/build.hpp"
#include "ivol/reader.hpp"
#include "ivol/structures.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

const std::string kReader = std::string(IVOL_SOURCE_DIR) + "/format-spec/reference-reader/ivolref.py";

int run_reference(const std::string& arguments, std::string* output = nullptr) {
  const std::string log = test::temp_path("ivolref.log");
  const std::string command = std::string(IVOL_PYTHON) + " " + kReader + " " + arguments + " > " + log + " 2>&1";
  const int status = std::system(command.c_str());
  const auto text = test::read_bytes(log);
  if (output) output->assign(text.begin(), text.end());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The reference reader's dense export and level of detail 1 of `path` are
// libformat's, byte for byte.
void expect_readers_agree(const std::string& path) {
  Reader reader(path);
  const Dims dims = reader.layout().dims;
  const std::string out = test::temp_path("ref.raw");
  std::string log;
  ASSERT_EQ(run_reference("dense " + path + " -o " + out, &log), 0) << log;
  EXPECT_EQ(test::read_bytes(out), reader.read_box_bits(full_box(dims))) << "dense export differs";
  // Level 1, and level 3: the first a bricked grid stores (spec §8A.5),
  // which libformat then reads from the file.
  for (const unsigned lod : {1u, 3u}) {
    if (reader.layout().depth < lod) break;
    ASSERT_EQ(run_reference("lod " + path + " " + std::to_string(lod) + " -o " + out, &log), 0) << log;
    EXPECT_EQ(test::read_bytes(out), reader.read_box_bits(full_box(dims, lod), lod))
        << "level of detail " << lod << " differs";
  }
}

TEST(ReferenceReader, PassesEveryConformanceVector) {
  std::string output;
  const int status =
      run_reference("conformance " + std::string(IVOL_SOURCE_DIR) + "/format-spec/vectors/manifest.json", &output);
  EXPECT_EQ(status, 0) << output;
  EXPECT_NE(output.find(" 0 failed"), std::string::npos) << output;
}

TEST(ReferenceReader, AgreesWithLibformatOnRandomFiles) {
  std::mt19937_64 rng(2026);
  std::uniform_int_distribution<std::uint32_t> side(1, 40);
  for (int n = 0; n < 14; ++n) {
    const Dims dims{side(rng), side(rng), side(rng)};
    const auto encoding = static_cast<ValueEncoding>(1 + n % 3);
    SCOPED_TRACE("file " + std::to_string(n) + ": " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                 std::to_string(dims[2]) + " " + encoding_name(encoding));
    const std::vector<float> volume = test::random_volume(dims, rng, n % 2 ? 0.1 : 0.0, 3);
    BuildOptions options;
    options.encoding = encoding;
    if (encoding == ValueEncoding::UInt16) options.value_scale = 1.0 / 1024;
    std::vector<std::uint8_t> keep;
    if (n % 4 == 3) {  // keep full resolution only in a random half-space
      keep.resize(volume.size());
      for (std::size_t i = 0; i < keep.size(); ++i) keep[i] = (i % dims[0]) < dims[0] / 2;
      options.keep_mask = keep.data();
    }
    WriteOptions w;
    w.block_bytes = 32u << (n % 8);
    w.compress = n % 5 != 0;
    const std::string path = test::temp_path("random-" + std::to_string(n) + ".ivol");
    Metadata m;
    m.user = {{"n", n}};
    write_octree(build_octree(volume.data(), dims, options).octree, m, path, w);

    expect_readers_agree(path);
  }
}

TEST(ReferenceReader, AgreesWithLibformatOnEveryStructureKind) {
  std::mt19937_64 rng(11);
  for (int n = 0; n < 9; ++n) {
    const Dims dims{7 + static_cast<std::uint32_t>(rng() % 30), 3 + static_cast<std::uint32_t>(rng() % 20),
                    1 + static_cast<std::uint32_t>(rng() % 25)};
    const std::uint32_t factor = 1u << (rng() % 3);
    NeedMask mask;
    mask.dims = dims;
    mask.factor = factor;
    mask.cells = {(dims[0] + factor - 1) / factor, (dims[1] + factor - 1) / factor, (dims[2] + factor - 1) / factor};
    mask.need.resize(voxel_count(mask.cells));
    for (auto& c : mask.need) c = rng() % 5 == 0;
    const std::vector<float> volume = test::random_volume(dims, rng, 0.1, 3);
    for (StructureKind kind : {StructureKind::Regular, StructureKind::Rectilinear, StructureKind::Nested}) {
      GenerationOptions generation;
      generation.nested_cell = 2u << (n % 3);
      generation.rectilinear_max_interval = 3 + n;
      const auto structure = generate_structure(kind, mask, generation);
      structure->sample_dense(volume.data());
      StreamingOptions options;
      options.build.encoding = static_cast<ValueEncoding>(1 + n % 3);
      if (options.build.encoding == ValueEncoding::UInt16) options.build.value_scale = 1.0 / 512;
      options.write.block_bytes = 64u << (n % 4);
      options.write.compress = n % 2 == 0;
      const std::string path = test::temp_path("grid-" + std::to_string(n) + ".ivol");
      write_structure(*structure, path, Metadata{}, options);
      SCOPED_TRACE(std::string(structure_name(kind)) + " " + std::to_string(n));
      expect_readers_agree(path);
    }
  }
}

// Bricked regular grids (spec §8A.4) with codec 3 (§7.2): the reference
// reader decodes them from the spec's formulas, libformat from its own code.
TEST(ReferenceReader, AgreesWithLibformatOnBrickedGrids) {
  std::mt19937 rng(22);
  std::normal_distribution<float> noise(0.0f, 0.00002f);
  const Dims shapes[] = {{19, 13, 9}, {8, 8, 8}, {1, 17, 5}};
  int predicted_files = 0;
  for (const Dims& d : shapes)
    for (ValueEncoding e : {ValueEncoding::Binary16, ValueEncoding::UInt16}) {
      std::vector<std::uint16_t> v(voxel_count(d));
      for (std::size_t i = 0; i < v.size(); ++i) {
        const std::size_t x = i % d[0], y = i / d[0] % d[1], z = i / d[0] / d[1];
        const float m = 0.01f + 0.0007f * static_cast<float>(x + 2 * y + 3 * z) + noise(rng);
        v[i] = e == ValueEncoding::UInt16 ? static_cast<std::uint16_t>(m * 500000.0f) : float_to_binary16(m);
      }
      if (e == ValueEncoding::Binary16) v[3] = 0x8000, v[5] = 0x7E13, v[v.size() - 1] = 0xFC00;
      BrickedOptions o;
      o.brick_log2 = d[0] == 8 ? 3 : 2;
      o.encoding = e;
      const std::string path = test::temp_path("bricked_ref.ivol");
      BrickedGridWriter writer(path, d, o);
      while (writer.next_layer_count() > 0)
        writer.add_layer(v.data() + std::size_t{writer.next_layer_first()} * d[0] * d[1]);
      writer.finish(Metadata{});
      bool predicted = false;
      const Reader written(path);  // a named reader: the loop walks its block table
      for (const BlockInfo& b : written.info().blocks) predicted = predicted || b.codec == 3;
      predicted_files += predicted;
      expect_readers_agree(path);
    }
  EXPECT_GE(predicted_files, 4);  // tiny bricks may be smaller under codec 2 or stored
}

// Bricked grids of float32 values (codec 2 bricks, stored levels of
// detail of float32): the reference reader decodes them from the spec.
TEST(ReferenceReader, AgreesWithLibformatOnFloat32BrickedGrids) {
  std::mt19937 rng(24);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  const Dims shapes[] = {{19, 13, 9}, {16, 16, 16}};
  for (const Dims& d : shapes) {
    std::vector<std::uint32_t> v(voxel_count(d));
    for (std::size_t i = 0; i < v.size(); ++i) {
      const std::size_t x = i % d[0], y = i / d[0] % d[1], z = i / d[0] / d[1];
      const float m = 0.01f + 0.0007f * static_cast<float>(x + 2 * y + 3 * z) + noise(rng);
      std::memcpy(&v[i], &m, 4);
    }
    v[3] = 0x80000000u, v[5] = 0x7FC01234u, v[v.size() - 1] = 0xFF800000u;
    BrickedOptions o;
    o.brick_log2 = 2;
    o.encoding = ValueEncoding::Float32;
    const std::string path = test::temp_path("bricked32_ref.ivol");
    BrickedGridWriter writer(path, d, o);
    while (writer.next_layer_count() > 0)
      writer.add_layer(v.data() + std::size_t{writer.next_layer_first()} * d[0] * d[1]);
    writer.finish(Metadata{});
    std::set<unsigned> codecs, streams;
    const Reader written(path);
    for (const BlockInfo& b : written.info().blocks) codecs.insert(b.codec), streams.insert(b.stream);
    EXPECT_TRUE(codecs.count(2)) << "bricks of byte planes";
    EXPECT_TRUE(streams.count(7)) << "stored levels of detail";
    expect_readers_agree(path);
  }
}

// Bricked grids of object fidelity (one background value around a part)
// with codec 4 (§7.3), both forms: the reference reader decodes them from
// the spec, libformat from its own code.
TEST(ReferenceReader, AgreesWithLibformatOnMaskedBricks) {
  std::mt19937 rng(23);
  const Dims shapes[] = {{19, 13, 9}, {16, 16, 16}};
  for (const Dims& d : shapes)
    for (std::uint16_t background : {std::uint16_t{0x8000}, std::uint16_t{0x7E01}, std::uint16_t{300}}) {
      std::vector<std::uint16_t> v(voxel_count(d), background);
      for (std::size_t i = 0; i < v.size(); ++i) {
        const std::size_t x = i % d[0], y = i / d[0] % d[1], z = i / d[0] / d[1];
        if (x * x + y * y + z * z < 60) v[i] = static_cast<std::uint16_t>(rng());
      }
      BrickedOptions o;
      o.brick_log2 = 2;
      o.encoding = background == 300 ? ValueEncoding::UInt16 : ValueEncoding::Binary16;
      const std::string path = test::temp_path("bricked_masked_ref.ivol");
      BrickedGridWriter writer(path, d, o);
      while (writer.next_layer_count() > 0)
        writer.add_layer(v.data() + std::size_t{writer.next_layer_first()} * d[0] * d[1]);
      writer.finish(Metadata{});
      const Reader written(path);
      const auto bytes = test::read_bytes(path);
      int forms[2] = {0, 0};
      for (const BlockInfo& b : written.info().blocks)
        if (b.codec == 4) ++forms[bytes[b.file_offset + 32 + 2] & 1];
      EXPECT_GT(forms[0], 0);  // bricks of the background alone
      EXPECT_GT(forms[1], 0);  // bricks at the part's surface
      expect_readers_agree(path);
    }
}

TEST(ReferenceReader, RefusesWhatLibformatRefuses) {
  const Dims dims{9, 9, 9};
  const std::vector<float> volume(voxel_count(dims), 0.5f);
  const std::string path = test::temp_path("to-damage.ivol");
  write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, Metadata{}, path);
  auto bytes = test::read_bytes(path);
  bytes[45] ^= 0x20;  // inside the first block
  const std::string damaged = test::temp_path("damaged-ref.ivol");
  test::write_bytes(damaged, bytes);
  std::string log;
  EXPECT_EQ(run_reference("check " + damaged, &log), 1) << log;
  EXPECT_NE(log.find("error: checksum"), std::string::npos) << log;
}

}  // namespace
