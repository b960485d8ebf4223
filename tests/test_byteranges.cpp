// multipart/byteranges bodies (RFC 9110 §14.6) as servers write them, built
// here by hand from the RFC's grammar: the parts and their Content-Range,
// a quoted boundary, a preamble, and the malformed bodies that must be
// refused whole (the reader then fetches the ranges one by one).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "byteranges.hpp"

namespace ivol::detail {
namespace {

std::vector<std::uint8_t> bytes(const std::string& text) { return {text.begin(), text.end()}; }

const std::string kTwoParts =
    "\r\n--THIS_STRING\r\nContent-Type: application/octet-stream\r\nContent-Range: bytes 0-3/20\r\n\r\nABCD"
    "\r\n--THIS_STRING\r\ncontent-range: bytes 10-14/20\r\n\r\nK\r\nMN"
    "\r\n--THIS_STRING--\r\n";

TEST(ByteRanges, BoundaryFromTheContentType) {
  EXPECT_EQ(byteranges_boundary("multipart/byteranges; boundary=THIS_STRING"), "THIS_STRING");
  EXPECT_EQ(byteranges_boundary("Multipart/ByteRanges; Boundary=\"a b;c\"; x=y"), "a b;c");
  EXPECT_EQ(byteranges_boundary("multipart/byteranges; boundary=00000000000000000001\r\n"), "00000000000000000001");
  EXPECT_EQ(byteranges_boundary("application/octet-stream"), "");
  EXPECT_EQ(byteranges_boundary("multipart/byteranges"), "");
}

TEST(ByteRanges, PartsAndTheirRanges) {
  const auto body = bytes(kTwoParts);
  std::vector<BytePart> parts;
  ASSERT_TRUE(parse_byteranges(body.data(), body.size(), "THIS_STRING", parts));
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].begin, 0u);
  EXPECT_EQ(parts[0].total, 20u);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(parts[0].data), parts[0].size), "ABCD");
  EXPECT_EQ(parts[1].begin, 10u);
  // The data may hold CRLF: the part ends where its range says, not at a search.
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(parts[1].data), parts[1].size), "K\r\nMN");
}

TEST(ByteRanges, MalformedBodiesAreRefusedWhole) {
  std::vector<BytePart> parts;
  const std::vector<std::string> bad = {
      "",                                                                         // nothing
      kTwoParts.substr(0, kTwoParts.size() - 20),                                 // cut before the close delimiter
      "\r\n--THIS_STRING\r\nContent-Type: x\r\n\r\nABCD\r\n--THIS_STRING--\r\n",  // no Content-Range
      "\r\n--THIS_STRING\r\nContent-Range: bytes 0-5/20\r\n\r\nABCD\r\n--THIS_STRING--\r\n",  // shorter than its range
      "\r\n--THIS_STRING\r\nContent-Range: bytes 0-1/20\r\n\r\nABCD\r\n--THIS_STRING--\r\n",  // longer than its range
      "\r\n--THIS_STRING\r\nContent-Range: bytes 5-3/20\r\n\r\n\r\n--THIS_STRING--\r\n",      // a range backwards
      "\r\n--THIS_STRING\r\nContent-Range: bytes 0-3/2\r\n\r\nABCD\r\n--THIS_STRING--\r\n",   // beyond the file
      "\r\n--THIS_STRING--\r\n",                                                              // no part at all
  };
  for (const std::string& text : bad) {
    const auto body = bytes(text);
    EXPECT_FALSE(parse_byteranges(body.data(), body.size(), "THIS_STRING", parts)) << text;
  }
  const auto body = bytes(kTwoParts);
  EXPECT_FALSE(parse_byteranges(body.data(), body.size(), "OTHER", parts));
  EXPECT_FALSE(parse_byteranges(body.data(), body.size(), "", parts));
}

}  // namespace
}  // namespace ivol::detail
