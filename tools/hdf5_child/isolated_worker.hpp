// Running a third-party parser in a child process, so that a crash inside it
// becomes an error naming the file instead of the end of ivol.
//
// Why: Debian 12's libhdf5 1.10.8 reads out of bounds or through a null
// pointer on some damaged files (tests/fuzz/regressions/libhdf5). ivol cannot
// fix the library, but it can keep it away from its own memory: the worker
// forks, the child alone calls the library, and the parent talks to it over
// a socket. If the child dies (a signal, or a sanitizer's exit), the parent
// throws ivol::Error(Malformed) naming the file, the request and the signal;
// a clean ivol::Error in the child is passed back with its class and message.
//
// The child is a fork without exec, so it starts with the parent's memory
// and descriptors (libhdf5's own state among them, which may name files the
// parent has open). It reads the file it was started for and writes only to
// the socket, is killed when the parent dies (PR_SET_PDEATHSIG) or drops the
// worker, and leaves through _exit, so none of the parent's atexit handlers
// or buffered output runs twice. Whatever descriptor or lock it shares with
// the parent thus ends with the parent. Readers start their worker when they
// are opened, before a converter or a reconstruction allocates its large
// buffers, so the fork copies little.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "wire.hpp"

namespace ivol::convert {

// What the child does with one request: fill `reply` (small results) and,
// for bulk data, `bulk` (sent without a copy into the reply). An exception
// is sent back to the parent instead.
struct WorkerReply {
  std::string reply;
  std::vector<char> bulk;
};
using WorkerHandler = std::function<void(std::string_view request, WorkerReply& out)>;

// What a library in a child process may allocate when the caller gives no
// budget: a damaged file can ask for gigabytes (a 4x4x4 dataset in one
// 4 GiB gzip chunk).
constexpr std::uint64_t kDefaultChildMemory = std::uint64_t{1} << 30;

class IsolatedWorker {
 public:
  // Starts the child. `subject` names what it works on, for messages (the
  // file's path); `library` names what runs there ("libhdf5"). The child
  // may allocate `memory_limit` bytes (0: kDefaultChildMemory) beyond what
  // it inherited, plus twice each request's bulk reply (RLIMIT_AS, set
  // before each request; not in sanitizer builds or under valgrind, whose
  // own reservations it would count). An allocation refused there is
  // ivol::Error(LimitExceeded) naming the file and the limit.
  IsolatedWorker(std::string subject, std::string library, WorkerHandler handler, std::uint64_t memory_limit = 0);
  ~IsolatedWorker();  // closes the socket and reaps the child
  IsolatedWorker(const IsolatedWorker&) = delete;
  IsolatedWorker& operator=(const IsolatedWorker&) = delete;

  // Sends `request` and returns the reply. When the request expects bulk
  // data, its size must be `bulk_bytes` and it lands in `bulk`. `doing`
  // describes the request for the message if the child dies ("reading
  // slices 0 .. 16"). Rethrows the child's ivol::Error.
  std::string call(const std::string& request, const std::string& doing, void* bulk = nullptr,
                   std::size_t bulk_bytes = 0);

  pid_t child() const { return child_; }
  std::uint64_t memory_limit() const { return memory_limit_; }

 private:
  [[noreturn]] void fail(const std::string& doing);

  std::string subject_;
  std::string library_;
  std::uint64_t memory_limit_ = 0;
  std::uint64_t resident_at_start_ = 0;  // the child's share of the parent's memory
  int socket_ = -1;
  pid_t child_ = -1;
};

}  // namespace ivol::convert
