// Running a third-party parser in a child process, so that a crash inside it
// becomes an error naming the file instead of the end of ivol.
//
// Why: Debian 12's libhdf5 1.10.8 reads out of bounds or through a null
// pointer on some damaged files (tests/fuzz/regressions/libhdf5). ivol cannot
// fix the library, but it can keep it away from its own memory: the child
// alone calls the library, and the parent talks to it over a socket. If the
// child dies (a signal, or a sanitizer's exit), the parent throws
// ivol::Error(Malformed) naming the file, the request and the signal; a clean
// ivol::Error in the child is passed back with its class and message.
//
// The child is a fresh process: the parent forks and the child at once
// executes the program's own binary again (/proc/self/exe), which becomes a
// worker in serve_if_worker_process() before it does anything else. A fork
// without exec would inherit the parent's threads' locks (MPI's and OpenCL's
// threads, an allocator's lock held at the moment of the fork) and could
// hang in the library's first malloc; only async-signal-safe calls are made
// between the fork and the exec. The child gets the socket and no other
// descriptor of the parent's, unblocked signals, is killed when the parent
// dies (PR_SET_PDEATHSIG) or drops the worker.
//
// What the child does is a *worker kind*: a name registered with a factory
// (WorkerKind) that makes the request handler from the parameters the parent
// sends first. Every program that starts workers calls
// serve_if_worker_process() first thing in main() (ivol's main, the tests'
// main, the fuzz harnesses' LLVMFuzzerInitialize).
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

// Makes a worker's handler from the parameters its parent sent. Runs in the
// child; what it throws ends the child before its first reply.
using WorkerFactory = WorkerHandler (*)(std::string_view parameters);

// Registers a worker kind under `name` (a namespace-scope object, so the
// kind exists before main() runs in the child).
struct WorkerKind {
  WorkerKind(const char* name, WorkerFactory factory);
};

// In a process started as a worker (the parent's environment variable
// IVOL_ISOLATED_WORKER names the socket), serves requests until the parent
// goes away and exits; returns at once in any other process.
void serve_if_worker_process();

// What a library in a child process may allocate when the caller gives no
// budget: a damaged file can ask for gigabytes (a 4x4x4 dataset in one
// 4 GiB gzip chunk).
constexpr std::uint64_t kDefaultChildMemory = std::uint64_t{1} << 30;

class IsolatedWorker {
 public:
  // Starts the child as a worker of the registered `kind`, made from
  // `parameters`. `subject` names what it works on, for messages (the
  // file's path); `library` names what runs there ("libhdf5"). The child
  // may allocate `memory_limit` bytes (0: kDefaultChildMemory) beyond what
  // it inherited, plus 16 MiB for the library's own tables and plugins and
  // twice each request's bulk reply (RLIMIT_AS, set
  // before each request; not in sanitizer builds or under valgrind, whose
  // own reservations it would count). An allocation refused there is
  // ivol::Error(LimitExceeded) naming the file and the limit.
  IsolatedWorker(std::string subject, std::string library, const std::string& kind, const std::string& parameters,
                 std::uint64_t memory_limit = 0);
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
  std::uint64_t resident_at_start_ = 0;  // the child's resident memory before its exec (the fork's copy)
  int socket_ = -1;
  pid_t child_ = -1;
};

}  // namespace ivol::convert
