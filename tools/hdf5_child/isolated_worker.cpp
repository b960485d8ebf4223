#include "isolated_worker.hpp"

#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <fstream>
#include <new>

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

// The child: the parent's signal handling is not its own, and it must not
// outlive the parent. It keeps the parent's descriptors: libhdf5's state,
// copied by the fork, may name files the parent has open, and a descriptor
// closed here would be reused under it.
void detach_from_parent(pid_t parent) {
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != parent) _exit(0);
  sigset_t all;
  sigfillset(&all);
  sigprocmask(SIG_UNBLOCK, &all, nullptr);
  for (int signal_number : {SIGTERM, SIGINT, SIGHUP, SIGPIPE}) std::signal(signal_number, SIG_DFL);
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

// The soft limit only: the next request may need more and raises it again.
void limit_address_space(std::uint64_t bytes) {
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0) return;
  limit.rlim_cur = limit.rlim_max == RLIM_INFINITY ? bytes : std::min<rlim_t>(bytes, limit.rlim_max);
  setrlimit(RLIMIT_AS, &limit);
}

[[noreturn]] void serve(int fd, const WorkerHandler& handler, std::uint64_t memory_limit) {
  const bool limited = address_space_is_ours();
  const std::uint64_t inherited = limited ? address_space_bytes() : 0;
  std::string request;
  WorkerReply out;
  std::uint64_t bulk_expected = 0;
  while (receive_all(fd, &bulk_expected, sizeof bulk_expected) && receive_text(fd, request)) {
    if (limited) limit_address_space(inherited + memory_limit + 2 * bulk_expected);
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

}  // namespace

IsolatedWorker::IsolatedWorker(std::string subject, std::string library, WorkerHandler handler,
                               std::uint64_t memory_limit)
    : subject_(std::move(subject)),
      library_(std::move(library)),
      memory_limit_(memory_limit ? memory_limit : kDefaultChildMemory) {
  int ends[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0)
    throw Error(ErrorClass::Io, subject_ + ": cannot start a process for " + library_ + ": " + std::strerror(errno));
  const pid_t parent = getpid();
  resident_at_start_ = resident_bytes();
  child_ = fork();
  if (child_ < 0) {
    const int saved = errno;
    close(ends[0]);
    close(ends[1]);
    throw Error(ErrorClass::Io, subject_ + ": cannot start a process for " + library_ + ": " + std::strerror(saved));
  }
  if (child_ == 0) {
    close(ends[0]);
    detach_from_parent(parent);
    serve(ends[1], handler, memory_limit_);
  }
  close(ends[1]);
  socket_ = ends[0];
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
