#include "http_source.hpp"

#include <curl/curl.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <iterator>
#include <list>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "byteranges.hpp"
#include "ivol/error.hpp"
#include "remote_target.hpp"

namespace ivol::detail {
namespace {

constexpr std::uint64_t kPage = 64 * 1024;
// What the open fetches of the file's start (header, metadata); the reader
// asks for the footer and the index exactly (file_index.cpp).
constexpr std::uint64_t kOpenBytes = 16 * 1024;

std::uint64_t cache_budget() {
  const char* text = std::getenv("IVOL_HTTP_CACHE_MIB");
  const long mib = text ? std::strtol(text, nullptr, 10) : 0;
  return (mib > 0 ? static_cast<std::uint64_t>(mib) : 64) << 20;
}

// Attempts of one request before its failure is reported: object stores
// answer 503 under load and drop connections, and a reader of a large file
// makes thousands of requests.
int attempts_allowed() {
  const char* text = std::getenv("IVOL_HTTP_RETRIES");
  const long retries = text ? std::strtol(text, nullptr, 10) : 4;
  return 1 + static_cast<int>(std::clamp<long>(retries, 0, 20));
}

// Whether to ask for several ranges in one request. Object stores (S3,
// GCS, MinIO) answer such a request with the whole object, so only servers
// known to answer it with multipart/byteranges are asked, by the Server
// header of their first response: nginx, Apache httpd, lighttpd.
// IVOL_HTTP_MULTIRANGE=1 asks any server, =0 none.
bool several_ranges_expected(const std::string& server) {
  const char* text = std::getenv("IVOL_HTTP_MULTIRANGE");
  if (text && std::strcmp(text, "0") == 0) return false;
  if (text && std::strcmp(text, "1") == 0) return true;
  for (const char* known : {"nginx", "Apache", "lighttpd"})
    if (server.rfind(known, 0) == 0) return true;
  return false;
}

// Waits before attempt `attempt` (2, 3, ...): 0.25 s, doubling, at most 4 s.
void back_off(int attempt) {
  std::this_thread::sleep_for(std::chrono::milliseconds(std::min(4000, 250 << std::min(attempt - 2, 5))));
}

// Failures of the connection or of an overloaded server, not of the
// request: worth another attempt.
bool transient(CURLcode code, long status) {
  switch (code) {
    case CURLE_COULDNT_CONNECT:
    case CURLE_SEND_ERROR:
    case CURLE_RECV_ERROR:
    case CURLE_PARTIAL_FILE:
    case CURLE_GOT_NOTHING:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
      return true;
    case CURLE_OK:
      return status == 429 || status == 500 || status == 502 || status == 503 || status == 504;
    default:
      return false;
  }
}

// What a final status other than 206 means, for the error message.
std::string status_meaning(long status) {
  switch (status) {
    case 401:
    case 403:
      return " (access denied: a pre-signed URL may have expired, or the object needs credentials: s3:// paths are "
             "signed with AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY)";
    case 404:
      return " (no such file on the server)";
    case 429:
    case 503:
      return " (the server is busy)";
    default:
      return "";
  }
}

void global_init() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

struct Response {
  long status = 0;  // of the last status line (redirects start anew)
  std::vector<std::uint8_t> body;
  std::string content_range;
  std::string content_type;
  std::string server;
  std::string etag;
  std::string last_modified;
  std::uint64_t limit = 0;        // the body may not grow beyond this
  std::uint64_t whole_limit = 0;  // nor beyond this, when it is the whole file (200)
  bool several = false;           // asked for several ranges
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
    const char* space = static_cast<const char*>(std::memchr(line, ' ', length));
    r->status = space ? std::strtol(space + 1, nullptr, 10) : 0;
    r->content_range.clear();
    r->content_type.clear();
    r->etag.clear();
    r->last_modified.clear();
  }
  if (auto v = header_value(line, length, "Content-Range"); !v.empty()) r->content_range = v;
  if (auto v = header_value(line, length, "Content-Type"); !v.empty()) r->content_type = v;
  if (auto v = header_value(line, length, "Server"); !v.empty()) r->server = v;
  if (auto v = header_value(line, length, "ETag"); !v.empty()) r->etag = v;
  if (auto v = header_value(line, length, "Last-Modified"); !v.empty()) r->last_modified = v;
  return length;
}

std::size_t on_body(char* data, std::size_t size, std::size_t count, void* user) {
  auto* r = static_cast<Response*>(user);
  const std::size_t length = size * count;
  // An error page (a 503's, a 404's) is not the file: not kept, not a reason
  // to stop the transfer (its status is what counts).
  if (r->status >= 300) return length;
  // A server that does not answer several ranges at once sends the whole
  // file instead: stopped at its first bytes.
  if (r->status == 200 && r->several) return 0;
  const std::uint64_t limit = r->status == 200 && r->whole_limit > 0 ? r->whole_limit : r->limit;
  if (r->body.size() + length > limit) {
    r->overflow = true;
    return 0;  // more than asked for: stop the transfer
  }
  r->body.insert(r->body.end(), data, data + length);
  return length;
}

class HttpSource final : public ByteSource {
 public:
  explicit HttpSource(const std::string& path)
      : url_(path), target_(resolve_remote_target(path)), budget_(cache_budget()), attempts_(attempts_allowed()) {
    global_init();
    curl_ = curl_easy_init();
    if (!curl_) throw Error(ErrorClass::LimitExceeded, path + ": cannot start libcurl");
    // The file's first bytes: the header (and with metadata first, the
    // metadata); its Content-Range gives the file's size and its ETag the
    // version. kOpenBytes, not a page: on a file of a few MB a page at each
    // end was 6 % of it, more than a slice's bricks on their own.
    try {
      Response first = fetch(0, kOpenBytes - 1, /*first=*/true);
      several_ranges_ = several_ranges_expected(first.server) ? Support::Unknown : Support::No;
      if (whole_)
        store(0, first.body);
      else
        keep_span(0, std::move(first.body));
    } catch (...) {
      curl_easy_cleanup(curl_);  // the destructor does not run for a constructor that throws
      curl_ = nullptr;
      throw;
    }
  }
  ~HttpSource() override {
    for (CURL* h : handles_) curl_easy_cleanup(h);
    if (multi_) curl_multi_cleanup(multi_);
    if (curl_) curl_easy_cleanup(curl_);
  }

  std::uint64_t size() const override { return size_; }
  std::uint64_t requests() const override { return requests_; }
  std::uint64_t bytes_fetched() const override { return fetched_; }
  bool fetched_whole() const override { return whole_; }

  void read(std::uint64_t offset, void* out, std::size_t size) override {
    auto* p = static_cast<std::uint8_t*>(out);
    if (read_from_spans(offset, p, size)) return;
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

  // The ranges a read is about to need, fetched exactly (not as whole pages:
  // a slice's blocks are a few KiB each, scattered) in one request per run
  // of ranges less than kMergeGap apart, at most kParallel requests at a
  // time; held as spans until read or until the budget needs the room.
  void prefetch(const std::vector<std::pair<std::uint64_t, std::uint64_t>>& ranges) override {
    std::vector<std::pair<std::uint64_t, std::uint64_t>> wanted;  // [begin, end)
    for (const auto& [offset, size] : ranges)
      if (size > 0 && offset < size_ && !covered(offset, size))
        wanted.emplace_back(offset, std::min(offset + size, size_));
    std::sort(wanted.begin(), wanted.end());
    std::vector<std::pair<std::uint64_t, std::uint64_t>> runs;
    const std::uint64_t longest = std::max<std::uint64_t>(budget_ / 4, kPage);
    for (const auto& [begin, end] : wanted) {
      if (!runs.empty() && begin <= runs.back().second + kMergeGap &&
          std::max(end, runs.back().second) - runs.back().first <= longest)
        runs.back().second = std::max(runs.back().second, end);
      else
        runs.emplace_back(begin, end);
    }
    if (runs.size() > 1 && several_ranges_ != Support::No) runs = fetch_several_per_request(runs);
    for (std::size_t at = 0; at < runs.size(); at += kParallel) {
      const std::size_t count = std::min(kParallel, runs.size() - at);
      std::vector<Response> got = fetch_parallel(runs.data() + at, count);
      for (std::size_t i = 0; i < count; ++i) keep_span(runs[at + i].first, std::move(got[i].body));
    }
  }

 private:
  // Ranges closer than this are fetched as one: a request costs a round
  // trip, a few KiB more of a response almost nothing.
  static constexpr std::uint64_t kMergeGap = 4 * 1024;
  static constexpr std::size_t kParallel = 8;
  // Ranges in one request when the server answers several at once
  // (multipart/byteranges, as nginx and Apache do; S3 does not): a slice
  // across bricks then costs a few requests instead of one per brick. An x
  // slice of a 512^3 grid of 16^3 bricks meets 1024 separate bricks; 200 a
  // request is Apache's default limit (MaxRanges), and 200 ranges of 24
  // bytes stay within nginx's 8 KiB header line.
  static constexpr std::size_t kRangesPerRequest = 200;
  static constexpr std::uint64_t kRequestBytes = 1u << 20;

  using Run = std::pair<std::uint64_t, std::uint64_t>;  // [begin, end)
  enum class Support { Unknown, Yes, No };
  struct Transfer {
    Response response;
    CURLcode code = CURLE_OK;
    long status = 0;
  };

  // The runs fetched several to a request, kParallel requests at a time;
  // returns those still missing (the server answered otherwise, or a
  // transfer failed), for the one-range path, which retries and reports.
  // A request gathers runs up to kRequestBytes, or an eighth of the whole
  // when that is more, and kRangesPerRequest: a small read is one request,
  // a large one still spreads over parallel connections. The first request
  // goes alone: a server that does not answer several ranges at once sends
  // the whole file (200), which is cut off at its first bytes, and the
  // runs then go one to a request.
  std::vector<Run> fetch_several_per_request(const std::vector<Run>& runs) {
    std::uint64_t total = 0;
    for (const Run& run : runs) total += run.second - run.first;
    const std::uint64_t target = std::max<std::uint64_t>(kRequestBytes, total / kParallel);
    std::vector<std::vector<Run>> groups(1);
    std::uint64_t bytes = 0;
    for (const Run& run : runs) {
      if (!groups.back().empty() && (bytes >= target || groups.back().size() == kRangesPerRequest)) {
        groups.emplace_back();
        bytes = 0;
      }
      groups.back().push_back(run);
      bytes += run.second - run.first;
    }
    std::size_t g = 0;
    if (several_ranges_ == Support::Unknown && groups[0].size() > 1) {
      std::vector<Transfer> probe = transfer_parallel({groups[0]});
      several_ranges_ = accept_parts(probe[0]) ? Support::Yes : Support::No;
      g = 1;
    }
    for (; g < groups.size() && several_ranges_ == Support::Yes; g += kParallel) {
      const std::vector<std::vector<Run>> batch(
          groups.begin() + static_cast<std::ptrdiff_t>(g),
          groups.begin() + static_cast<std::ptrdiff_t>(std::min(g + kParallel, groups.size())));
      for (Transfer& t : transfer_parallel(batch)) accept_parts(t);
    }
    std::vector<Run> missing;
    for (const Run& run : runs)
      if (!covered(run.first, run.second - run.first)) missing.push_back(run);
    return missing;
  }

  // Keeps the parts of a response to a request for several ranges; false
  // when it is not a usable 206 (the runs are then fetched one by one).
  bool accept_parts(Transfer& t) {
    tally(t.response);
    if (t.status == 412) fail(ErrorClass::Io, "the file changed on the server while it was open (HTTP 412)");
    if (t.code != CURLE_OK || t.status != 206 || t.response.overflow) return false;
    std::vector<BytePart> parts;
    const std::vector<std::uint8_t>& body = t.response.body;
    const std::string boundary = byteranges_boundary(t.response.content_type);
    if (boundary.empty()) {  // the server merged the ranges into one
      unsigned long long first = 0, last = 0, total = 0;
      if (std::sscanf(t.response.content_range.c_str(), "bytes %llu-%llu/%llu", &first, &last, &total) != 3 ||
          last < first || body.size() != last - first + 1)
        return false;
      parts.push_back({first, total, body.data(), body.size()});
    } else if (!parse_byteranges(body.data(), body.size(), boundary, parts)) {
      return false;
    }
    for (const BytePart& part : parts) {
      if (part.total != size_)
        fail(ErrorClass::Io, "the file's size changed on the server from " + std::to_string(size_) + " to " +
                                 std::to_string(part.total) + " bytes while it was open");
      keep_span(part.begin, std::vector<std::uint8_t>(part.data, part.data + part.size));
    }
    return true;
  }

  bool covered(std::uint64_t offset, std::uint64_t size) const {
    auto it = spans_.upper_bound(offset);
    if (it != spans_.begin() && offset + size <= std::prev(it)->first + std::prev(it)->second.size()) return true;
    for (std::uint64_t page = offset / kPage; page <= (offset + size - 1) / kPage; ++page)
      if (!pages_.count(page)) return false;
    return true;
  }

  bool read_from_spans(std::uint64_t offset, std::uint8_t* out, std::size_t size) {
    auto it = spans_.upper_bound(offset);
    if (it == spans_.begin()) return false;
    --it;
    const std::vector<std::uint8_t>& bytes = it->second;
    if (offset + size > it->first + bytes.size()) return false;
    std::memcpy(out, bytes.data() + (offset - it->first), size);
    return true;
  }

  void keep_span(std::uint64_t offset, std::vector<std::uint8_t> bytes) {
    // Spans share the page cache's budget; the oldest go first, never the
    // one just fetched.
    span_held_ += bytes.size();
    span_order_.push_back(offset);
    spans_[offset] = std::move(bytes);
    while (span_held_ > budget_ && span_order_.size() > 1) {
      const auto old = spans_.find(span_order_.front());
      span_order_.pop_front();
      if (old == spans_.end()) continue;
      span_held_ -= old->second.size();
      spans_.erase(old);
    }
  }

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
      entry.bytes.assign(
          bytes.begin() + static_cast<std::ptrdiff_t>(at),
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

  // Sets up `handle` to fetch bytes [begin, end] into `r`; *headers is
  // freed by the caller after the transfer.
  void configure(CURL* handle, Response& r, const std::string& range, bool first, curl_slist** headers) const {
    curl_easy_reset(handle);
    curl_easy_setopt(handle, CURLOPT_URL, target_.url.c_str());
    curl_easy_setopt(handle, CURLOPT_RANGE, range.c_str());
    curl_easy_setopt(handle, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(handle, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(handle, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(handle, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(handle, CURLOPT_CONNECTTIMEOUT, 30L);
    curl_easy_setopt(handle, CURLOPT_LOW_SPEED_LIMIT, 1024L);
    curl_easy_setopt(handle, CURLOPT_LOW_SPEED_TIME, 60L);
    curl_easy_setopt(handle, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(handle, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(handle, CURLOPT_HEADERDATA, &r);
    curl_easy_setopt(handle, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(handle, CURLOPT_WRITEDATA, &r);
    *headers = nullptr;
    if (!target_.aws_sigv4.empty()) {
      curl_easy_setopt(handle, CURLOPT_AWS_SIGV4, target_.aws_sigv4.c_str());
      curl_easy_setopt(handle, CURLOPT_USERPWD, target_.credentials.c_str());
    }
    for (const std::string& header : target_.headers) *headers = curl_slist_append(*headers, header.c_str());
    if (!first && !version_.empty()) {
      const std::string condition = (etag_.empty() ? "If-Unmodified-Since: " : "If-Match: ") + version_;
      *headers = curl_slist_append(*headers, condition.c_str());
    }
    if (*headers) curl_easy_setopt(handle, CURLOPT_HTTPHEADER, *headers);
  }

  // Bytes [begin, end], attempted up to attempts_ times (after `failed`
  // attempts already made elsewhere) while the failure is transient.
  Response fetch(std::uint64_t begin, std::uint64_t end, bool first, int failed = 0) {
    const std::string range = std::to_string(begin) + "-" + std::to_string(end);
    for (int attempt = failed + 1;; ++attempt) {
      if (attempt > 1) back_off(attempt);
      Response r;
      r.limit = end - begin + 1;
      // A server that ignores ranges may send the whole file, once, up to
      // the cache's size; never again after the open.
      if (first) r.whole_limit = budget_;
      curl_slist* headers = nullptr;
      configure(curl_, r, range, first, &headers);
      const CURLcode code = curl_easy_perform(curl_);
      if (headers) curl_slist_free_all(headers);
      long status = 0;
      curl_easy_getinfo(curl_, CURLINFO_RESPONSE_CODE, &status);
      tally(r);
      if (attempt < attempts_ && transient(code, status)) continue;
      check(r, code, status, begin, end, first, attempt);
      return r;
    }
  }

  void tally(const Response& r) {
    ++requests_;
    fetched_ += r.body.size();
  }

  // Requests sent at the same time, one connection each (the handles and
  // their connections are kept for the next batch); request i asks for the
  // runs of requests[i], as one range or several.
  std::vector<Transfer> transfer_parallel(const std::vector<std::vector<Run>>& requests) {
    const std::size_t count = requests.size();
    if (!multi_) multi_ = curl_multi_init();
    if (!multi_) throw Error(ErrorClass::LimitExceeded, url_ + ": cannot start libcurl");
    while (handles_.size() < count) {
      CURL* h = curl_easy_init();
      if (!h) throw Error(ErrorClass::LimitExceeded, url_ + ": cannot start libcurl");
      handles_.push_back(h);
    }
    std::vector<Transfer> out(count);
    std::vector<std::string> range(count);
    std::vector<curl_slist*> headers(count, nullptr);
    for (std::size_t i = 0; i < count; ++i) {
      std::uint64_t bytes = 0;
      for (const Run& run : requests[i]) {
        range[i] += (range[i].empty() ? "" : ",") + std::to_string(run.first) + "-" + std::to_string(run.second - 1);
        bytes += run.second - run.first;
      }
      // Several ranges come as parts, each with a few lines of headers.
      out[i].response.limit = requests[i].size() == 1 ? bytes : bytes + 256 * requests[i].size() + 1024;
      out[i].response.several = requests[i].size() > 1;
      configure(handles_[i], out[i].response, range[i], false, &headers[i]);
      curl_multi_add_handle(multi_, handles_[i]);
    }
    int running = 0;
    do {
      if (curl_multi_perform(multi_, &running) != CURLM_OK) break;
      if (running) curl_multi_poll(multi_, nullptr, 0, 1000, nullptr);
    } while (running);
    int left = 0;
    while (CURLMsg* m = curl_multi_info_read(multi_, &left))
      if (m->msg == CURLMSG_DONE)
        for (std::size_t i = 0; i < count; ++i)
          if (m->easy_handle == handles_[i]) out[i].code = m->data.result;
    for (std::size_t i = 0; i < count; ++i) {
      curl_multi_remove_handle(multi_, handles_[i]);
      if (headers[i]) curl_slist_free_all(headers[i]);
      curl_easy_getinfo(handles_[i], CURLINFO_RESPONSE_CODE, &out[i].status);
    }
    return out;
  }

  // Runs [begin, end) fetched at the same time, a range to a request.
  std::vector<Response> fetch_parallel(const Run* runs, std::size_t count) {
    if (count == 1) return {fetch(runs[0].first, runs[0].second - 1, false)};
    std::vector<std::vector<Run>> requests;
    for (std::size_t i = 0; i < count; ++i) requests.push_back({runs[i]});
    std::vector<Transfer> done = transfer_parallel(requests);
    std::vector<Response> out(count);
    for (std::size_t i = 0; i < count; ++i) {
      Transfer& t = done[i];
      tally(t.response);
      // A dropped connection or a busy server: that range again, alone.
      if (attempts_ > 1 && transient(t.code, t.status)) {
        out[i] = fetch(runs[i].first, runs[i].second - 1, false, /*failed=*/1);
      } else {
        check(t.response, t.code, t.status, runs[i].first, runs[i].second - 1, false, 1);
        out[i] = std::move(t.response);
      }
    }
    return out;
  }

  // Counts a response and refuses what is not exactly the asked range.
  void check(Response& r, CURLcode code, long status, std::uint64_t begin, std::uint64_t end, bool first,
             int attempts) {
    const std::string range = std::to_string(begin) + "-" + std::to_string(end);
    const std::string tries = attempts > 1 ? " after " + std::to_string(attempts) + " attempts" : "";
    if (first && status == 200 && code == CURLE_OK && !r.overflow) {
      size_ = r.body.size();
      whole_ = true;
      etag_ = r.etag;
      version_ = r.etag.empty() ? r.last_modified : r.etag;
      return;
    }
    if (first && status == 200 && r.overflow)
      fail(ErrorClass::LimitExceeded,
           "the server does not answer range requests (HTTP 200), and the file is larger "
           "than the " +
               std::to_string(budget_ >> 20) + " MiB a whole download may hold (IVOL_HTTP_CACHE_MIB)");
    if (status == 200 || (r.overflow && status != 206))
      fail(ErrorClass::InvalidArgument, "the server does not answer range requests (HTTP " + std::to_string(status) +
                                            " for bytes " + range +
                                            "); ivol reads remote files by range only, never whole");
    if (status == 412) fail(ErrorClass::Io, "the file changed on the server while it was open (HTTP 412)");
    if (status == 416 && first) fail(ErrorClass::Truncated, "the file is empty (HTTP 416)");
    if (code != CURLE_OK)
      fail(ErrorClass::Io, std::string("cannot read bytes ") + range + tries + ": " + curl_easy_strerror(code));
    if (status != 206)
      fail(ErrorClass::Io, "HTTP " + std::to_string(status) + status_meaning(status) + " for bytes " + range + tries);
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
      fail(ErrorClass::Io, "asked for bytes " + range + ", received " + std::to_string(r.body.size()) + " bytes as '" +
                               r.content_range + "'");
  }

  std::string url_;  // as given: what errors name
  RemoteTarget target_;
  std::uint64_t budget_;
  int attempts_;
  CURL* curl_ = nullptr;
  std::uint64_t size_ = 0;
  std::string etag_, version_;
  bool whole_ = false;  // the server ignored ranges; every page is held
  Support several_ranges_ = Support::No;
  std::map<std::uint64_t, Page> pages_;
  std::list<std::uint64_t> lru_;
  std::uint64_t held_ = 0;
  std::map<std::uint64_t, std::vector<std::uint8_t>> spans_;  // exact ranges prefetch() fetched, by offset
  std::deque<std::uint64_t> span_order_;                      // their offsets, oldest first
  std::uint64_t span_held_ = 0;
  CURLM* multi_ = nullptr;
  std::vector<CURL*> handles_;  // prefetch()'s parallel transfers
  std::uint64_t requests_ = 0;
  std::uint64_t fetched_ = 0;
};

}  // namespace

std::unique_ptr<ByteSource> open_http_source(const std::string& url) { return std::make_unique<HttpSource>(url); }

}  // namespace ivol::detail
