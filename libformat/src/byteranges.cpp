#include "byteranges.hpp"

#include <strings.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace ivol::detail {
namespace {

std::string lower(std::string text) {
  for (char& c : text) c = static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  return text;
}

const std::uint8_t* find(const std::uint8_t* from, const std::uint8_t* end, const std::string& what) {
  if (what.empty() || static_cast<std::size_t>(end - from) < what.size()) return nullptr;
  const auto* at = std::search(from, end, what.begin(), what.end());
  return at == end ? nullptr : at;
}

}  // namespace

std::string byteranges_boundary(const std::string& content_type) {
  const std::string type = lower(content_type);
  if (type.rfind("multipart/byteranges", 0) != 0) return {};
  const auto key = type.find("boundary=");
  if (key == std::string::npos) return {};
  std::string boundary = content_type.substr(key + 9);  // the original case
  if (!boundary.empty() && boundary.front() == '"') {
    const auto close = boundary.find('"', 1);
    if (close == std::string::npos) return {};
    return boundary.substr(1, close - 1);
  }
  return boundary.substr(0, boundary.find_first_of("; \t\r\n"));
}

bool parse_byteranges(const std::uint8_t* body, std::size_t size, const std::string& boundary,
                      std::vector<BytePart>& parts) {
  parts.clear();
  if (boundary.empty()) return false;
  const std::string delimiter = "--" + boundary;
  const std::uint8_t* end = body + size;
  const std::uint8_t* at = find(body, end, delimiter);
  while (at) {
    at += delimiter.size();
    if (end - at >= 2 && at[0] == '-' && at[1] == '-') return !parts.empty();  // the close delimiter
    const std::uint8_t* headers_end = find(at, end, "\r\n\r\n");
    if (!headers_end) return false;
    // Content-Range among the part's headers.
    BytePart part;
    bool ranged = false;
    for (const std::uint8_t* line = at; line < headers_end;) {
      const std::uint8_t* eol = find(line, headers_end + 2, "\r\n");
      if (!eol) return false;
      const std::string text(reinterpret_cast<const char*>(line), static_cast<std::size_t>(eol - line));
      unsigned long long first = 0, last = 0, total = 0;
      if (text.size() > 14 && strncasecmp(text.c_str(), "content-range:", 14) == 0 &&
          std::sscanf(text.c_str() + 14, " bytes %llu-%llu/%llu", &first, &last, &total) == 3 && first <= last &&
          last < total) {
        part.begin = first;
        part.total = total;
        part.size = static_cast<std::size_t>(last - first + 1);
        ranged = true;
      }
      line = eol + 2;
    }
    const std::uint8_t* data = headers_end + 4;
    if (!ranged || static_cast<std::uint64_t>(end - data) < part.size) return false;
    part.data = data;
    parts.push_back(part);
    // The next delimiter follows the data after a CRLF.
    const std::uint8_t* next = data + part.size;
    if (end - next < 2 || next[0] != '\r' || next[1] != '\n') return false;
    at = next + 2;
    if (static_cast<std::size_t>(end - at) < delimiter.size() ||
        std::memcmp(at, delimiter.data(), delimiter.size()) != 0)
      return false;
  }
  return false;
}

}  // namespace ivol::detail
