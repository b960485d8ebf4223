// Integrity: every single-byte change and every truncation of a file is
// detected by check_file, which names the damaged part; one damaged block
// does not hide another.
#include <gtest/gtest.h>

#include <random>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

class Corruption : public ::testing::Test {
 protected:
  void SetUp() override {
    const Dims dims{12, 10, 9};
    std::mt19937_64 rng(21);
    const std::vector<float> volume = test::random_volume(dims, rng, 0.1, 3);
    Metadata m;
    m.provenance = {{"software", {{"name", "ivol-test"}}}};
    WriteOptions w;
    w.block_bytes = 128;  // several blocks per level
    path_ = test::temp_path("small.ivol");
    write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, m, path_, w);
    original_ = test::read_bytes(path_);
    Reader reader(path_);
    info_ = reader.info();
    ASSERT_TRUE(check_file(path_).ok());
  }

  // The part of the file a byte belongs to, as check_file names it.
  std::string part_of(std::uint64_t offset) const {
    if (offset < info_.header_size) return "header";
    if (offset >= info_.file_size - 32) return "footer";
    if (offset >= info_.index_offset) return "index";
    for (std::size_t b = 0; b < info_.blocks.size(); ++b)
      if (offset < info_.blocks[b].file_offset + info_.blocks[b].stored_size)
        return "block " + std::to_string(b) + " (";
    return "?";
  }

  CheckReport check_bytes(const std::vector<std::uint8_t>& bytes) {
    const std::string damaged = test::temp_path("damaged.ivol");
    test::write_bytes(damaged, bytes);
    return check_file(damaged);
  }

  std::string path_;
  std::vector<std::uint8_t> original_;
  FileInfo info_;
};

TEST_F(Corruption, EverySingleByteChangeIsDetectedAndLocated) {
  ASSERT_GT(info_.blocks.size(), 10u);
  std::size_t checked = 0;
  for (std::size_t at = 0; at < original_.size(); ++at) {
    for (std::uint8_t flip : {0x01, 0x80, 0xFF}) {
      std::vector<std::uint8_t> bytes = original_;
      bytes[at] ^= flip;
      const CheckReport report = check_bytes(bytes);
      ASSERT_FALSE(report.ok()) << "byte " << at << " ^ " << int(flip) << " went unnoticed";
      const std::string part = part_of(at);
      bool named = false;
      for (const auto& p : report.problems) named = named || p.message.find(part) != std::string::npos;
      // A changed header byte may also read as a bad signature or version, a
      // changed footer byte as a truncated file: those name the header or footer.
      ASSERT_TRUE(named) << "byte " << at << " (" << part << "): " << report.problems[0].message;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 3 * original_.size());
}

TEST_F(Corruption, EveryTruncationAndExtensionIsDetected) {
  for (std::size_t length = 0; length < original_.size(); ++length) {
    const std::vector<std::uint8_t> bytes(original_.begin(), original_.begin() + static_cast<long>(length));
    const CheckReport report = check_bytes(bytes);
    ASSERT_FALSE(report.ok()) << "truncation to " << length << " bytes went unnoticed";
    if (length >= 8) ASSERT_EQ(report.problems[0].error_class, ErrorClass::Truncated) << length;
  }
  std::vector<std::uint8_t> longer = original_;
  longer.push_back(0);
  EXPECT_EQ(check_bytes(longer).problems.at(0).error_class, ErrorClass::Truncated);
}

TEST_F(Corruption, OneDamagedBlockDoesNotHideAnother) {
  std::vector<std::uint8_t> bytes = original_;
  const BlockInfo& first = info_.blocks[2];
  const BlockInfo& second = info_.blocks[info_.blocks.size() - 3];
  bytes[first.file_offset] ^= 0x10;
  bytes[second.file_offset + second.stored_size - 1] ^= 0x10;
  const CheckReport report = check_bytes(bytes);
  EXPECT_EQ(report.blocks_damaged, 2u);
  EXPECT_EQ(report.blocks_checked, info_.blocks.size());
  ASSERT_EQ(report.problems.size(), 2u);
  EXPECT_EQ(report.problems[0].error_class, ErrorClass::Checksum);
  EXPECT_NE(report.problems[0].message.find("block 2 "), std::string::npos) << report.problems[0].message;
}

TEST_F(Corruption, ReaderRefusesDamagedBlockButReadsOtherRegions) {
  // Damage the last values block (finest level): coarse previews still read.
  std::vector<std::uint8_t> bytes = original_;
  std::size_t last_values = 0;
  for (std::size_t b = 0; b < info_.blocks.size(); ++b)
    if (info_.blocks[b].stream == 3) last_values = b;
  bytes[info_.blocks[last_values].file_offset + 1] ^= 0x01;
  const std::string damaged = test::temp_path("damaged-read.ivol");
  test::write_bytes(damaged, bytes);
  Reader reader(damaged);
  EXPECT_NO_THROW(reader.read_lod(2));
  try {
    reader.read_lod(0);
    FAIL() << "damage not reported";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::Checksum);
    EXPECT_NE(std::string(e.what()).find("block " + std::to_string(last_values)), std::string::npos) << e.what();
  }
}

TEST_F(Corruption, SalvageFillsDamagedRegionsFromCoarserLevels) {
  Reader intact(path_);
  const unsigned depth = intact.layout().depth;
  const std::vector<float> original = intact.read_lod(0);
  for (std::uint8_t stream : {std::uint8_t{3}, std::uint8_t{2}}) {
    // Damage the last block of the stream: the finest values, or the nodes
    // of the deepest inner level.
    std::size_t victim = 0;
    for (std::size_t b = 0; b < info_.blocks.size(); ++b)
      if (info_.blocks[b].stream == stream) victim = b;
    std::vector<std::uint8_t> bytes = original_;
    bytes[info_.blocks[victim].file_offset] ^= 0x40;
    const std::string damaged_path = test::temp_path("salvage.ivol");
    test::write_bytes(damaged_path, bytes);
    Reader reader(damaged_path);
    const Dims d = reader.layout().dims;
    std::vector<DamagedRegion> damaged;
    const std::vector<float> salvaged = reader.read_box(full_box(d), 0, &damaged);
    // One damaged block, one cause: its entries are the few exact boxes its
    // regions merge into (not one entry per voxel), each naming the block.
    ASSERT_FALSE(damaged.empty()) << "stream " << int(stream);
    EXPECT_LE(damaged.size(), 64u) << "stream " << int(stream);
    for (const DamagedRegion& r : damaged)
      EXPECT_NE(r.message.find("block " + std::to_string(victim) + " ("), std::string::npos) << r.message;
    std::vector<std::uint8_t> hit(salvaged.size(), 0);
    std::vector<std::vector<float>> coarse(depth + 1);
    for (unsigned lod = 1; lod <= depth; ++lod) coarse[lod] = intact.read_lod(lod);
    std::size_t filled = 0;
    for (const DamagedRegion& r : damaged) {
      // Inside the box, a voxel is as written or holds the average of a
      // level above the damage.
      for (std::uint32_t z = r.region.lo[2]; z < r.region.hi[2]; ++z)
        for (std::uint32_t y = r.region.lo[1]; y < r.region.hi[1]; ++y)
          for (std::uint32_t x = r.region.lo[0]; x < r.region.hi[0]; ++x) {
            const std::uint64_t at = (std::uint64_t{z} * d[1] + y) * d[0] + x;
            hit[at] = 1;
            if (salvaged[at] == original[at]) continue;
            ++filled;
            bool from_above = false;
            for (unsigned lod = depth - (r.level > 0 ? r.level - 1 : 0); lod <= depth && !from_above; ++lod) {
              const Dims cd = lod_dims(d, lod);
              from_above =
                  salvaged[at] == coarse[lod][(std::uint64_t{z >> lod} * cd[1] + (y >> lod)) * cd[0] + (x >> lod)];
            }
            if (stream == 3) ASSERT_TRUE(from_above) << x << "," << y << "," << z;
          }
    }
    EXPECT_GT(filled, 0u);
    // Everything outside the damaged regions is exactly as written.
    for (std::size_t i = 0; i < salvaged.size(); ++i)
      if (!hit[i]) ASSERT_EQ(salvaged[i], original[i]) << i;
    EXPECT_THROW(reader.read_lod(0), Error);  // without salvage the damage is an error
  }
}

}  // namespace
