// The body of a multipart/byteranges response (RFC 9110 §14.6), the answer
// of a server such as nginx to a request for several ranges at once: each
// part carries its own Content-Range. Parsed without copying; any deviation
// from the grammar (a missing boundary, a part without Content-Range, a
// part whose length differs from its range) makes the whole body unusable,
// and the caller fetches the ranges one by one instead.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ivol::detail {

struct BytePart {
  std::uint64_t begin = 0;  // first byte of the file in this part
  std::uint64_t total = 0;  // the file's size, as the part says
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
};

// The boundary of a "multipart/byteranges; boundary=..." Content-Type, or
// empty when the type is another.
std::string byteranges_boundary(const std::string& content_type);

// The parts of `body`, or false when it does not follow the grammar.
bool parse_byteranges(const std::uint8_t* body, std::size_t size, const std::string& boundary,
                      std::vector<BytePart>& parts);

}  // namespace ivol::detail
