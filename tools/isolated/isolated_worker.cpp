#include "isolated_worker.hpp"

#include <fcntl.h>
#include <malloc.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <new>
#include <vector>

#if defined(__has_include)
#if __has_include(<valgrind/valgrind.h>)
#include <valgrind/valgrind.h>
#endif
#endif

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

constexpr std::uint8_t kReplyOk = 0;
constexpr std::uint8_t kReplyError = 1;

// Whole writes and reads over the socket; false when the other end is gone.
// MSG_NOSIGNAL: a dead peer must give an error here, not SIGPIPE.
bool send_all(int fd, const void* data, std::size_t size) {
  const auto* bytes = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t sent = ::send(fd, bytes, size, MSG_NOSIGNAL);
    if (sent < 0 && errno == EINTR) continue;
    if (sent <= 0) return false;
    bytes += sent;
    size -= static_cast<std::size_t>(sent);
  }
  return true;
}

bool receive_all(int fd, void* data, std::size_t size) {
  auto* bytes = static_cast<char*>(data);
  while (size > 0) {
    const ssize_t got = ::recv(fd, bytes, size, 0);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    bytes += got;
    size -= static_cast<std::size_t>(got);
  }
  return true;
}

bool send_text(int fd, const std::string& text) {
  const std::uint64_t size = text.size();
  return send_all(fd, &size, sizeof size) && send_all(fd, text.data(), text.size());
}

bool receive_text(int fd, std::string& text) {
  std::uint64_t size = 0;
  if (!receive_all(fd, &size, sizeof size)) return false;
  text.resize(size);
  return receive_all(fd, text.data(), size);
}

// Sanitizers and valgrind reserve address space of their own as they go;
// a limit on it would stop them, not the library.
bool address_space_is_ours() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return false;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
  return false;
#endif
#endif
#ifdef RUNNING_ON_VALGRIND
  if (RUNNING_ON_VALGRIND) return false;
#endif
  return true;
}

// The process's address space and resident memory now (a child: what it
// inherited from the parent).
std::uint64_t address_space_bytes() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t pages = 0;
  statm >> pages;
  return pages * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}
std::uint64_t resident_bytes() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t size = 0, resident = 0;
  statm >> size >> resident;
  return resident * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}

// What the library holds of its own, whatever the request: libhdf5's
// metadata cache (2 MiB to start) and free lists, filter plugins mapped on
// first use (blosc and its codecs). Without it, a budget of a few MiB left
// less than a MiB to spare in reading bands of rows of a 15 MB slice.
constexpr std::uint64_t kLibraryReserve = std::uint64_t{16} << 20;

// The soft limit only: the next request may need more and raises it again.
void limit_address_space(std::uint64_t bytes) {
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0) return;
  limit.rlim_cur = limit.rlim_max == RLIM_INFINITY ? bytes : std::min<rlim_t>(bytes, limit.rlim_max);
  setrlimit(RLIMIT_AS, &limit);
}

[[noreturn]] void serve(int fd, const WorkerHandler& handler, std::uint64_t memory_limit) {
  const bool limited = address_space_is_ours();
  if (limited) {
    // The limit is what the library may hold now, so what is freed must
    // leave the address space: glibc otherwise raises its mmap threshold to
    // the largest block freed (up to 32 MiB) and serves the next ones from
    // a heap it keeps, and a limit that was enough for one request was not
    // for the next of the same size.
    mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    mallopt(M_TRIM_THRESHOLD, 128 * 1024);
  }
  const std::uint64_t inherited = limited ? address_space_bytes() : 0;
  std::string request;
  WorkerReply out;
  std::uint64_t bulk_expected = 0;
  while (receive_all(fd, &bulk_expected, sizeof bulk_expected) && receive_text(fd, request)) {
    // A reply larger than this one still held would count against this
    // request's limit, which allows only for its own (the last band of
    // rows of a slice is shorter than the others).
    if (out.bulk.capacity() > bulk_expected) std::vector<char>().swap(out.bulk);
    if (limited) limit_address_space(inherited + memory_limit + kLibraryReserve + 2 * bulk_expected);
    out.reply.clear();
    out.bulk.clear();
    std::uint8_t error_class = 0;
    std::string error;
    try {
      handler(request, out);
    } catch (const Error& e) {
      error_class = static_cast<std::uint8_t>(e.error_class());
      error = e.what();
    } catch (const std::bad_alloc&) {
      error_class = static_cast<std::uint8_t>(ErrorClass::LimitExceeded);
      error = "out of memory";
    } catch (const std::exception& e) {
      error_class = static_cast<std::uint8_t>(ErrorClass::Malformed);
      error = e.what();
    }
    if (error_class == static_cast<std::uint8_t>(ErrorClass::LimitExceeded) && limited)
      error += " (the process that runs the library may allocate " + std::to_string(memory_limit >> 20) +
               " MiB; --memory MiB raises it)";
    bool sent;
    if (error.empty()) {
      const std::uint64_t bulk = out.bulk.size();
      sent = send_all(fd, &kReplyOk, 1) && send_text(fd, out.reply) && send_all(fd, &bulk, sizeof bulk) &&
             send_all(fd, out.bulk.data(), out.bulk.size());
    } else {
      sent = send_all(fd, &kReplyError, 1) && send_all(fd, &error_class, 1) && send_text(fd, error);
    }
    if (!sent) break;
  }
  _exit(0);
}

std::string describe_end(int status) {
  if (WIFSIGNALED(status)) {
    const int number = WTERMSIG(status);
    const char* name = strsignal(number);
    return "crashed (signal " + std::to_string(number) + (name ? std::string(", ") + name : std::string()) + ")";
  }
  // The child leaves without replying only when something stopped it: a
  // sanitizer's report (printed above), abort handlers.
  if (WIFEXITED(status)) return "crashed (exit status " + std::to_string(WEXITSTATUS(status)) + ")";
  return "crashed";
}

std::map<std::string, WorkerFactory>& worker_kinds() {
  static std::map<std::string, WorkerFactory> kinds;
  return kinds;
}

constexpr const char* kWorkerVariable = "IVOL_ISOLATED_WORKER";
// The socket's number in the child: after the standard streams.
constexpr int kChildSocket = 3;

// The binary to execute again. Under valgrind /proc/self/exe is valgrind's
// own tool, while readlink() on it gives the program's path; a binary
// replaced since it started reads "(deleted)", and /proc/self/exe still
// names the one that runs.
std::string own_binary() {
  std::vector<char> buffer(4096);
  const ssize_t length = readlink("/proc/self/exe", buffer.data(), buffer.size() - 1);
  if (length <= 0 || static_cast<std::size_t>(length) >= buffer.size() - 1) return "/proc/self/exe";
  std::string path(buffer.data(), static_cast<std::size_t>(length));
  const std::string deleted = " (deleted)";
  if (path.size() > deleted.size() && path.compare(path.size() - deleted.size(), deleted.size(), deleted) == 0)
    return "/proc/self/exe";
  return path;
}

// Between fork and exec: system calls only (async-signal-safe). The child
// must not outlive the parent, starts with every signal unblocked and at its
// default (a blocked or ignored signal survives exec), and keeps only the
// standard streams and the socket.
[[noreturn]] void become_worker(pid_t parent, int socket, const char* binary, char* const argv[],
                                char* const envp[]) {
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != parent) _exit(0);
  struct sigaction default_action {};
  default_action.sa_handler = SIG_DFL;
  for (int number = 1; number < NSIG; ++number) sigaction(number, &default_action, nullptr);
  sigset_t all;
  sigfillset(&all);
  sigprocmask(SIG_UNBLOCK, &all, nullptr);
  if (socket != kChildSocket) {
    if (dup2(socket, kChildSocket) < 0) _exit(127);
  } else {
    fcntl(kChildSocket, F_SETFD, 0);
  }
  close_range(kChildSocket + 1, ~0U, 0);
  execve(binary, argv, envp);
  _exit(127);
}

}  // namespace

WorkerKind::WorkerKind(const char* name, WorkerFactory factory) { worker_kinds()[name] = factory; }

void serve_if_worker_process() {
  const char* variable = std::getenv(kWorkerVariable);
  if (!variable) return;
  const int fd = std::atoi(variable);
  unsetenv(kWorkerVariable);  // the worker's own children are not workers
  std::string kind, parameters;
  std::uint64_t memory_limit = 0;
  if (!receive_text(fd, kind) || !receive_text(fd, parameters) ||
      !receive_all(fd, &memory_limit, sizeof memory_limit))
    _exit(0);
  const auto found = worker_kinds().find(kind);
  if (found == worker_kinds().end()) {
    // The parent sees the end of the socket and reports the exit status.
    std::fprintf(stderr, "ivol: internal error: no worker kind \"%s\" in this program\n", kind.c_str());
    _exit(126);
  }
  WorkerHandler handler;
  try {
    handler = found->second(parameters);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ivol: internal error: worker kind \"%s\": %s\n", kind.c_str(), e.what());
    _exit(126);
  }
  serve(fd, handler, memory_limit);
}

IsolatedWorker::IsolatedWorker(std::string subject, std::string library, const std::string& kind,
                               const std::string& parameters, std::uint64_t memory_limit)
    : subject_(std::move(subject)),
      library_(std::move(library)),
      memory_limit_(memory_limit ? memory_limit : kDefaultChildMemory) {
  auto cannot_start = [&](int error) {
    return Error(ErrorClass::Io,
                 subject_ + ": cannot start a process for " + library_ + ": " + std::strerror(error));
  };
  if (worker_kinds().count(kind) == 0)
    throw Error(ErrorClass::InvalidArgument, subject_ + ": no worker kind \"" + kind + "\" for " + library_);
  int ends[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) throw cannot_start(errno);
  // Everything the child needs is made here: after the fork it may only
  // make system calls.
  const std::string binary = own_binary();
  std::string argv0 = "ivol-worker:" + kind;
  char* const argv[] = {argv0.data(), nullptr};
  std::vector<std::string> environment;
  for (char** entry = environ; entry && *entry; ++entry)
    if (std::strncmp(*entry, kWorkerVariable, std::strlen(kWorkerVariable)) != 0 ||
        (*entry)[std::strlen(kWorkerVariable)] != '=')
      environment.emplace_back(*entry);
  environment.push_back(std::string(kWorkerVariable) + "=" + std::to_string(kChildSocket));
  std::vector<char*> envp;
  for (std::string& entry : environment) envp.push_back(entry.data());
  envp.push_back(nullptr);
  const pid_t parent = getpid();
  resident_at_start_ = resident_bytes();
  child_ = fork();
  if (child_ < 0) {
    const int saved = errno;
    close(ends[0]);
    close(ends[1]);
    throw cannot_start(saved);
  }
  if (child_ == 0) become_worker(parent, ends[1], binary.c_str(), argv, envp.data());
  close(ends[1]);
  socket_ = ends[0];
  const std::uint64_t limit = memory_limit_;
  if (!send_text(socket_, kind) || !send_text(socket_, parameters) || !send_all(socket_, &limit, sizeof limit))
    fail("starting");
}

IsolatedWorker::~IsolatedWorker() {
  if (socket_ >= 0) close(socket_);
  if (child_ > 0) {
    // Nothing the child still does is wanted; a child stuck in the library
    // must not keep the parent waiting.
    kill(child_, SIGKILL);
    while (waitpid(child_, nullptr, 0) < 0 && errno == EINTR) {
    }
  }
}

void IsolatedWorker::fail(const std::string& doing) {
  int status = 0;
  pid_t ended = -1;
  rusage usage{};
  do ended = wait4(child_, &status, 0, &usage);
  while (ended < 0 && errno == EINTR);
  child_ = -1;
  close(socket_);
  socket_ = -1;
  // 127: the exec failed; 126: the binary has no such worker kind.
  if (ended > 0 && WIFEXITED(status) && (WEXITSTATUS(status) == 127 || WEXITSTATUS(status) == 126))
    throw Error(ErrorClass::Io, subject_ + ": the process for " + library_ + " did not start (" +
                                    (WEXITSTATUS(status) == 127 ? "ivol's binary could not be executed again"
                                                                : "ivol's binary has no such worker") +
                                    ")");
  const std::string how = ended > 0 ? describe_end(status) : "stopped answering";
  // A library that dies when an allocation is refused (a null pointer it
  // did not check) or that the kernel kills for memory ran out of its
  // limit, which is not a damaged file: tell them apart by the child's peak.
  const std::uint64_t peak = static_cast<std::uint64_t>(usage.ru_maxrss) * 1024;
  const std::uint64_t grew = peak > resident_at_start_ ? peak - resident_at_start_ : 0;
  if (ended > 0 && WIFSIGNALED(status) && address_space_is_ours() && grew >= memory_limit_ / 4 * 3)
    throw Error(ErrorClass::LimitExceeded, subject_ + ": " + library_ + " " + how + " while " + doing +
                                               " after allocating " + std::to_string(grew >> 20) + " MiB, near the " +
                                               std::to_string(memory_limit_ >> 20) +
                                               " MiB its process may allocate (--memory MiB raises it)");
  throw Error(ErrorClass::Malformed, subject_ + ": " + library_ + " " + how + " while " + doing +
                                         ": the file is damaged or not what it claims to be (" + library_ +
                                         " ran in a process of its own; nothing else was affected)");
}

std::string IsolatedWorker::call(const std::string& request, const std::string& doing, void* bulk,
                                 std::size_t bulk_bytes) {
  if (socket_ < 0)
    throw Error(ErrorClass::InvalidArgument, subject_ + ": " + library_ + " was stopped by an earlier failure");
  const std::uint64_t bulk_expected = bulk_bytes;
  if (!send_all(socket_, &bulk_expected, sizeof bulk_expected) || !send_text(socket_, request)) fail(doing);
  std::uint8_t status = 0;
  if (!receive_all(socket_, &status, 1)) fail(doing);
  if (status == kReplyError) {
    std::uint8_t error_class = 0;
    std::string message;
    if (!receive_all(socket_, &error_class, 1) || !receive_text(socket_, message)) fail(doing);
    throw Error(static_cast<ErrorClass>(error_class), message);
  }
  std::string reply;
  std::uint64_t size = 0;
  if (!receive_text(socket_, reply) || !receive_all(socket_, &size, sizeof size)) fail(doing);
  if (size != bulk_bytes || (size > 0 && !bulk)) {
    // The rest of this reply is still in the socket: the worker cannot be
    // used again.
    close(socket_);
    socket_ = -1;
    throw Error(ErrorClass::Malformed, subject_ + ": " + library_ + " returned " + std::to_string(size) +
                                           " bytes while " + doing + "; " + std::to_string(bulk_bytes) +
                                           " were expected");
  }
  if (!receive_all(socket_, bulk, size)) fail(doing);
  return reply;
}

}  // namespace ivol::convert
