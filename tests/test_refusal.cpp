// Files a reader must refuse (spec §13), each with its error class and a
// message naming the part; and what a reader must accept and ignore.
#include <gtest/gtest.h>

#include <cstring>

#include "ivol/build.hpp"
#include "ivol/check.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/writer.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

class Refusal : public ::testing::Test {
 protected:
  void SetUp() override {
    const Dims dims{6, 5, 7};
    std::vector<float> volume(voxel_count(dims));
    for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = (i % 11 < 4) ? 1.0f : static_cast<float>(i % 7);
    WriteOptions w;
    w.compress = false;  // stored blocks, so that tests can patch elements
    path_ = test::temp_path("refusal.ivol");
    write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, Metadata{}, path_, w);
    bytes_ = test::read_bytes(path_);
    info_ = Reader(path_).info();
  }

  std::size_t index_at(std::size_t field) const { return info_.index_offset + field; }
  std::size_t entry_at(std::size_t block, std::size_t field) const {
    return info_.index_offset + 48 + 8 * (info_.layout.depth + 1) + 32 * block + field;
  }

  // Where a block's elements begin: after the block header in a framed file.
  std::size_t payload_at(const BlockInfo& b) const { return b.file_offset + (info_.framed() ? 32 : 0); }

  // Sets element `element` of a stored stream and makes every checksum agree.
  void patch_element(std::uint8_t stream, std::uint64_t element, std::uint64_t bits, std::size_t width) {
    for (std::size_t b = 0; b < info_.blocks.size(); ++b) {
      const BlockInfo& blk = info_.blocks[b];
      if (blk.stream != stream || element < blk.first_element || element >= blk.first_element + blk.element_count)
        continue;
      std::memcpy(&bytes_[payload_at(blk) + (element - blk.first_element) * width], &bits, width);
      if (info_.framed()) {  // the block header's payload_crc and header_crc (spec §7.1)
        const std::uint32_t payload_crc = crc32c(&bytes_[payload_at(blk)], blk.stored_size - 32);
        std::memcpy(&bytes_[blk.file_offset + 24], &payload_crc, 4);
        const std::uint32_t header_crc = crc32c(&bytes_[blk.file_offset], 28);
        std::memcpy(&bytes_[blk.file_offset + 28], &header_crc, 4);
      }
      const std::uint32_t crc = crc32c(&bytes_[blk.file_offset], blk.stored_size);
      std::memcpy(&bytes_[entry_at(b, 24)], &crc, 4);
      test::refresh_container_checksums(bytes_);
      return;
    }
    FAIL() << "no block holds element " << element;
  }

  void expect_refused(ErrorClass expected, const std::string& words) {
    const std::string path = test::temp_path("refused.ivol");
    test::write_bytes(path, bytes_);
    const CheckReport report = check_file(path);
    ASSERT_FALSE(report.ok());
    EXPECT_EQ(report.problems[0].error_class, expected) << report.problems[0].message;
    EXPECT_NE(report.problems[0].message.find(words), std::string::npos) << report.problems[0].message;
  }

  std::string path_;
  std::vector<std::uint8_t> bytes_;
  FileInfo info_;
};

TEST_F(Refusal, NotAnIvolFile) {
  bytes_[1] = 'X';
  expect_refused(ErrorClass::NotIvol, "signature");
  test::write_bytes(test::temp_path("text.ivol"), std::vector<std::uint8_t>{'h', 'e', 'l', 'l', 'o'});
  EXPECT_EQ(check_file(test::temp_path("text.ivol")).problems.at(0).error_class, ErrorClass::NotIvol);
}

TEST_F(Refusal, TextModeDamageToTheSignature) {
  // CRLF -> LF conversion removes the 0D before 0A.
  bytes_.erase(bytes_.begin() + 5);
  expect_refused(ErrorClass::NotIvol, "signature");
}

TEST_F(Refusal, UnknownMajorVersion) {
  bytes_[8] = 2;
  expect_refused(ErrorClass::UnsupportedVersion, "version 2");
}

TEST_F(Refusal, UnknownRequiredFeature) {
  bytes_[16 + 2] = 0x01;  // bit 16
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::UnsupportedFeature, "bit(s) 16");
}

TEST_F(Refusal, UnknownOptionalFeatureIsIgnored) {
  bytes_[24 + 7] = 0x80;  // bit 63
  test::refresh_container_checksums(bytes_);
  test::write_bytes(test::temp_path("optional.ivol"), bytes_);
  EXPECT_TRUE(check_file(test::temp_path("optional.ivol")).ok());
}

TEST_F(Refusal, ReservedHeaderBytes) {
  bytes_[33] = 1;
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "reserved");
}

TEST_F(Refusal, HeaderChecksum) {
  bytes_[20] ^= 0x04;
  expect_refused(ErrorClass::Checksum, "header");
}

TEST_F(Refusal, UnknownStructureKindAndEncoding) {
  bytes_[index_at(8)] = 6;  // 5 is the bricked grid since 1.3
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::UnsupportedFeature, "structure_kind 6");
  bytes_[index_at(8)] = 1;
  bytes_[index_at(9)] = 4;
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::UnsupportedFeature, "value_encoding 4");
}

TEST_F(Refusal, DepthNotMinimal) {
  bytes_[index_at(10)] += 1;
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "depth");
}

TEST_F(Refusal, UnknownCodecAndStream) {
  bytes_[entry_at(0, 29)] = 9;
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::UnsupportedFeature, "codec 9");
  bytes_[entry_at(0, 29)] = 0;
  bytes_[entry_at(0, 28)] = 77;
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::UnsupportedFeature, "stream 77");
}

TEST_F(Refusal, BlocksMustTileTheFile) {
  std::uint64_t offset;
  std::memcpy(&offset, &bytes_[entry_at(1, 0)], 8);
  offset += 1;
  std::memcpy(&bytes_[entry_at(1, 0)], &offset, 8);
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "file_offset");
}

TEST_F(Refusal, IndexOutOfRange) {
  const std::size_t footer = bytes_.size() - 32;
  std::uint64_t offset = bytes_.size() + 100;
  std::memcpy(&bytes_[footer], &offset, 8);
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "footer");
}

TEST_F(Refusal, LevelTableRules) {
  std::uint64_t too_many = 2;
  std::memcpy(&bytes_[index_at(48)], &too_many, 8);  // inner_count[0]
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "level table");
}

TEST_F(Refusal, BlockDeclaringMoreThan64MiB) {
  const std::uint32_t huge = 40u << 20;  // 40 Mi values of 2 bytes: 80 MiB
  std::size_t values_block = 0;
  while (info_.blocks[values_block].stream != 3) ++values_block;
  std::memcpy(&bytes_[entry_at(values_block, 16)], &huge, 4);
  test::refresh_container_checksums(bytes_);
  expect_refused(ErrorClass::Malformed, "64 MiB");
}

TEST_F(Refusal, WrongFirstInnerChild) {
  std::uint64_t root = 0;
  for (const BlockInfo& b : info_.blocks)
    if (b.stream == 2 && b.first_element == 0) std::memcpy(&root, &bytes_[payload_at(b)], 8);
  ASSERT_NE(child_mask(root), 0);
  patch_element(2, 0, make_node_word(child_mask(root), first_inner_child(root) + 1), 8);
  expect_refused(ErrorClass::Malformed, "node 0");
}

TEST_F(Refusal, WrongAverage) {
  // Value 0 is the root's average; change its last bit.
  Reader reader(path_);
  const std::uint32_t root = reader.voxel_bits(0, 0, 0, reader.layout().depth);
  patch_element(3, 0, root ^ 1u, 2);
  expect_refused(ErrorClass::Malformed, "average");
}

TEST_F(Refusal, MetadataNotJsonOrMissingKeys) {
  for (const std::string& text :
       {std::string("{\"voxel_size\": [1,1,1], \"unit\": \"mm\""),
        std::string("{\"unit\": \"mm\", \"origin\": [0,0,0], \"value\": {\"quantity\": \"x\"}}"),
        std::string("{\"a\": 1, \"a\": 2}")}) {
    EXPECT_THROW(Metadata::parse(text), Error) << text;
  }
  const Metadata ok = Metadata::parse(
      R"({"voxel_size": [1,2,3], "unit": "um", "origin": [0,0,0], "value": {"quantity": "grey_value"}, "future_key": {"x": 1}})");
  EXPECT_EQ(ok.unit, "um");
  EXPECT_EQ(ok.to_json()["future_key"]["x"], 1);
}

}  // namespace
