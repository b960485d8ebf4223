// CRC-32C against the published check values (spec §2.1, RFC 3720 B.4) and a
// bit-by-bit implementation of the definition.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "ivol/crc32c.hpp"

namespace {

std::uint32_t crc_by_definition(const std::uint8_t* p, std::size_t n) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= p[i];
    for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ ((crc & 1u) ? 0x82F63B78u : 0u);
  }
  return crc ^ 0xFFFFFFFFu;
}

TEST(Crc32c, PublishedCheckValues) {
  EXPECT_EQ(ivol::crc32c("123456789", 9), 0xE3069283u);
  const std::vector<std::uint8_t> zeros(32, 0x00);
  const std::vector<std::uint8_t> ones(32, 0xFF);
  EXPECT_EQ(ivol::crc32c(zeros.data(), 32), 0x8A9136AAu);
  EXPECT_EQ(ivol::crc32c(ones.data(), 32), 0x62A8AB43u);
  std::vector<std::uint8_t> ascending(32);
  for (int i = 0; i < 32; ++i) ascending[i] = static_cast<std::uint8_t>(i);
  EXPECT_EQ(ivol::crc32c(ascending.data(), 32), 0x46DD794Eu);
  EXPECT_EQ(ivol::crc32c(nullptr, 0), 0u);
}

TEST(Crc32c, MatchesDefinitionForEveryLengthAndAlignment) {
  std::mt19937 rng(7);
  std::vector<std::uint8_t> data(300);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng());
  for (std::size_t start = 0; start < 9; ++start)
    for (std::size_t n = 0; start + n <= data.size(); n += 1 + n / 7)
      ASSERT_EQ(ivol::crc32c(data.data() + start, n), crc_by_definition(data.data() + start, n))
          << "start " << start << " length " << n;
}

TEST(Crc32c, ExtendEqualsWhole) {
  std::vector<std::uint8_t> data(1000);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i * 31 + 7);
  const std::uint32_t whole = ivol::crc32c(data.data(), data.size());
  for (std::size_t cut : {0u, 1u, 7u, 8u, 500u, 999u, 1000u})
    EXPECT_EQ(ivol::crc32c_extend(ivol::crc32c(data.data(), cut), data.data() + cut, data.size() - cut), whole);
}

TEST(Crc32c, DetectsEverySingleByteChange) {
  std::vector<std::uint8_t> data(64);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i);
  const std::uint32_t base = ivol::crc32c(data.data(), data.size());
  for (std::size_t i = 0; i < data.size(); ++i)
    for (int delta = 1; delta < 256; ++delta) {
      data[i] = static_cast<std::uint8_t>(data[i] + delta);
      ASSERT_NE(ivol::crc32c(data.data(), data.size()), base);
      data[i] = static_cast<std::uint8_t>(data[i] - delta);
    }
}

}  // namespace
