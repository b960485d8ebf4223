#include "http_source.hpp"

#include <curl/curl.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <list>
#include <map>
#include <mutex>
#include <vector>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

constexpr std::uint64_t kPage = 64 * 1024;

std::uint64_t cache_budget() {
  const char* text = std::getenv("IVOL_HTTP_CACHE_MIB");
  const long mib = text ? std::strtol(text, nullptr, 10) : 0;
  return (mib > 0 ? static_cast<std::uint64_t>(mib) : 64) << 20;
}

void global_init() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

struct Response {
  std::vector<std::uint8_t> body;
  std::string content_range;
  std::string etag;
  std::string last_modified;
  std::uint64_t limit = 0;  // the body may not grow beyond this
  bool overflow = false;
};

std::string header_value(const char* line, std::size_t length, const char* name) {
  const std::size_t n = std::strlen(name);
  if (length < n + 1 || strncasecmp(line, name, n) != 0 || line[n] != ':') return {};
  std::string value(line + n + 1, length - n - 1);
  const auto first = value.find_first_not_of(" \t");
  const auto last = value.find_last_not_of(" \t\r\n");
  return first == std::string::npos ? std::string() : value.substr(first, last - first + 1);
}

std::size_t on_header(char* line, std::size_t size, std::size_t count, void* user) {
  auto* r = static_cast<Response*>(user);
  const std::size_t length = size * count;
  // A redirect starts a new set of headers.
  if (length >= 5 && std::strncmp(line, "HTTP/", 5) == 0) {
    r->content_range.clear();
    r->etag.clear();
    r->last_modified.clear();
  }
  if (auto v = header_value(line, length, "Content-Range"); !v.empty()) r->content_range = v;
  if (auto v = header_value(line, length, "ETag"); !v.empty()) r->etag = v;
  if (auto v = header_value(line, length, "Last-Modified"); !v.empty()) r->last_modified = v;
  return length;
}

std::size_t on_body(char* data, std::size_t size, std::size_t count, void* user) {
  auto* r = static_cast<Response*>(user);
  const std::size_t length = size * count;
  if (r->body.size() + length > r->limit) {
    r->overflow = true;
    return 0;  // more than asked for: stop the transfer
  }
  r->body.insert(r->body.end(), data, data + length);
  return length;
}

class HttpSource final : public ByteSource {
 public:
  explicit HttpSource(const std::string& url) : url_(url), budget_(cache_budget()) {
    global_init();
    curl_ = curl_easy_init();
    if (!curl_) throw Error(ErrorClass::LimitExceeded, url + ": cannot start libcurl");
    // The first page: the header (and with metadata first, the metadata);
    // its Content-Range gives the file's size and its ETag the version.
    try {
      Response first = fetch(0, kPage - 1, /*first=*/true);
      store(0, first.body);
    } catch (...) {
      curl_easy_cleanup(curl_);  // the destructor does not run for a constructor that throws
      curl_ = nullptr;
      throw;
    }
  }
  ~HttpSource() override {
    if (curl_) curl_easy_cleanup(curl_);
  }

  std::uint64_t size() const override { return size_; }
  std::uint64_t requests() const override { return requests_; }
  std::uint64_t bytes_fetched() const override { return fetched_; }

  void read(std::uint64_t offset, void* out, std::size_t size) override {
    auto* p = static_cast<std::uint8_t*>(out);
    const std::uint64_t first = offset / kPage, last = (offset + size - 1) / kPage;
    // Missing pages, fetched a contiguous run at a time.
    for (std::uint64_t page = first; page <= last;) {
      if (pages_.count(page)) {
        ++page;
        continue;
      }
      std::uint64_t end = page;
      while (end + 1 <= last && !pages_.count(end + 1)) ++end;
      fetch_pages(page, end);
      page = end + 1;
    }
    for (std::uint64_t page = first; page <= last; ++page) {
      const auto found = pages_.find(page);
      if (found == pages_.end())
        throw Error(ErrorClass::LimitExceeded, url_ + ": a read of " + std::to_string(size) +
                                                   " bytes is larger than the HTTP page cache (IVOL_HTTP_CACHE_MIB)");
      touch(found);
      const std::vector<std::uint8_t>& bytes = found->second.bytes;
      const std::uint64_t page_start = page * kPage;
      const std::uint64_t from = std::max(offset, page_start);
      const std::uint64_t to = std::min<std::uint64_t>(offset + size, page_start + bytes.size());
      std::memcpy(p + (from - offset), bytes.data() + (from - page_start), to - from);
    }
  }

  void prefetch(const std::vector<std::pair<std::uint64_t, std::uint64_t>>& ranges) override {
    // Pages wanted, then runs of them merged over gaps of up to a page.
    std::vector<std::uint64_t> wanted;
    for (const auto& [offset, size] : ranges) {
      if (size == 0) continue;
      for (std::uint64_t page = offset / kPage; page <= (offset + size - 1) / kPage; ++page)
        if (!pages_.count(page)) wanted.push_back(page);
    }
    std::sort(wanted.begin(), wanted.end());
    wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
    const std::uint64_t room = std::max<std::uint64_t>(budget_ / kPage / 2, 1);
    for (std::size_t i = 0; i < wanted.size();) {
      std::size_t j = i;
      while (j + 1 < wanted.size() && wanted[j + 1] <= wanted[j] + 2 && wanted[j + 1] - wanted[i] < room) ++j;
      fetch_pages(wanted[i], wanted[j]);
      i = j + 1;
    }
  }

 private:
  struct Page {
    std::vector<std::uint8_t> bytes;
    std::list<std::uint64_t>::iterator age;
  };

  void touch(std::map<std::uint64_t, Page>::iterator page) {
    lru_.erase(page->second.age);
    lru_.push_front(page->first);
    page->second.age = lru_.begin();
  }

  void store(std::uint64_t first_page, const std::vector<std::uint8_t>& bytes) {
    for (std::uint64_t at = 0; at < bytes.size(); at += kPage) {
      const std::uint64_t page = first_page + at / kPage;
      if (pages_.count(page)) continue;
      lru_.push_front(page);
      Page entry;
      entry.bytes.assign(bytes.begin() + static_cast<std::ptrdiff_t>(at),
                         bytes.begin() + static_cast<std::ptrdiff_t>(std::min<std::uint64_t>(at + kPage, bytes.size())));
      entry.age = lru_.begin();
      held_ += entry.bytes.size();
      pages_.emplace(page, std::move(entry));
    }
    // Evict the least recently used, but never what was just stored.
    const std::uint64_t stored = (bytes.size() + kPage - 1) / kPage;
    while (held_ > budget_ && lru_.size() > stored) {
      const std::uint64_t old = lru_.back();
      lru_.pop_back();
      held_ -= pages_[old].bytes.size();
      pages_.erase(old);
    }
  }

  void fetch_pages(std::uint64_t first, std::uint64_t last) {
    const std::uint64_t begin = first * kPage;
    const std::uint64_t end = std::min((last + 1) * kPage, size_) - 1;
    if (begin > end) return;
    store(first, fetch(begin, end, false).body);
  }

  [[noreturn]] void fail(ErrorClass c, const std::string& what) const { throw Error(c, url_ + ": " + what); }

  Response fetch(std::uint64_t begin, std::uint64_t end, bool first) {
    Response r;
    r.limit = end - begin + 1;
    curl_easy_reset(curl_);
    const std::string range = std::to_string(begin) + "-" + std::to_string(end);
    curl_easy_setopt(curl_, CURLOPT_URL, url_.c_str());
    curl_easy_setopt(curl_, CURLOPT_RANGE, range.c_str());
    curl_easy_setopt(curl_, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(curl_, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(curl_, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(curl_, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(curl_, CURLOPT_CONNECTTIMEOUT, 30L);
    curl_easy_setopt(curl_, CURLOPT_LOW_SPEED_LIMIT, 1024L);
    curl_easy_setopt(curl_, CURLOPT_LOW_SPEED_TIME, 60L);
    curl_easy_setopt(curl_, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(curl_, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(curl_, CURLOPT_HEADERDATA, &r);
    curl_easy_setopt(curl_, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(curl_, CURLOPT_WRITEDATA, &r);
    curl_slist* headers = nullptr;
    if (!first && !version_.empty()) {
      const std::string condition = (etag_.empty() ? "If-Unmodified-Since: " : "If-Match: ") + version_;
      headers = curl_slist_append(headers, condition.c_str());
      curl_easy_setopt(curl_, CURLOPT_HTTPHEADER, headers);
    }
    const CURLcode code = curl_easy_perform(curl_);
    if (headers) curl_slist_free_all(headers);
    ++requests_;
    long status = 0;
    curl_easy_getinfo(curl_, CURLINFO_RESPONSE_CODE, &status);
    fetched_ += r.body.size();
    if (status == 200 || (r.overflow && status != 206))
      fail(ErrorClass::InvalidArgument,
           "the server does not answer range requests (HTTP " + std::to_string(status) +
               " for bytes " + range + "); ivol reads remote files by range only, never whole");
    if (status == 412) fail(ErrorClass::Io, "the file changed on the server while it was open (HTTP 412)");
    if (status == 416 && first) fail(ErrorClass::Truncated, "the file is empty (HTTP 416)");
    if (code != CURLE_OK)
      fail(ErrorClass::Io, std::string("cannot read bytes ") + range + ": " + curl_easy_strerror(code));
    if (status != 206) fail(ErrorClass::Io, "HTTP " + std::to_string(status) + " for bytes " + range);
    // "bytes BEGIN-END/TOTAL"
    std::uint64_t got_begin = 0, got_end = 0, total = 0;
    if (std::sscanf(r.content_range.c_str(), "bytes %lu-%lu/%lu", &got_begin, &got_end, &total) != 3)
      fail(ErrorClass::Io, "a range response without a usable Content-Range ('" + r.content_range + "')");
    if (first) {
      size_ = total;
      etag_ = r.etag;
      version_ = r.etag.empty() ? r.last_modified : r.etag;
    } else if (total != size_) {
      fail(ErrorClass::Io, "the file's size changed on the server from " + std::to_string(size_) + " to " +
                               std::to_string(total) + " bytes while it was open");
    }
    const std::uint64_t want_end = std::min(end, total - 1);
    if (got_begin != begin || got_end != want_end || r.body.size() != want_end - begin + 1)
      fail(ErrorClass::Io, "asked for bytes " + range + ", received " + std::to_string(r.body.size()) +
                               " bytes as '" + r.content_range + "'");
    return r;
  }

  std::string url_;
  std::uint64_t budget_;
  CURL* curl_ = nullptr;
  std::uint64_t size_ = 0;
  std::string etag_, version_;
  std::map<std::uint64_t, Page> pages_;
  std::list<std::uint64_t> lru_;
  std::uint64_t held_ = 0;
  std::uint64_t requests_ = 0;
  std::uint64_t fetched_ = 0;
};

}  // namespace

std::unique_ptr<ByteSource> open_http_source(const std::string& url) { return std::make_unique<HttpSource>(url); }

}  // namespace ivol::detail
