#include "isolated_worker.hpp"

#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <new>

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

[[noreturn]] void serve(int fd, const WorkerHandler& handler) {
  std::string request;
  WorkerReply out;
  while (receive_text(fd, request)) {
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

IsolatedWorker::IsolatedWorker(std::string subject, std::string library, WorkerHandler handler)
    : subject_(std::move(subject)), library_(std::move(library)) {
  int ends[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0)
    throw Error(ErrorClass::Io, subject_ + ": cannot start a process for " + library_ + ": " + std::strerror(errno));
  const pid_t parent = getpid();
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
    serve(ends[1], handler);
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
  do ended = waitpid(child_, &status, 0);
  while (ended < 0 && errno == EINTR);
  child_ = -1;
  close(socket_);
  socket_ = -1;
  const std::string how = ended > 0 ? describe_end(status) : "stopped answering";
  throw Error(ErrorClass::Malformed, subject_ + ": " + library_ + " " + how + " while " + doing +
                                         ": the file is damaged or not what it claims to be (" + library_ +
                                         " ran in a process of its own; nothing else was affected)");
}

std::string IsolatedWorker::call(const std::string& request, const std::string& doing, void* bulk,
                                 std::size_t bulk_bytes) {
  if (socket_ < 0)
    throw Error(ErrorClass::InvalidArgument, subject_ + ": " + library_ + " was stopped by an earlier failure");
  if (!send_text(socket_, request)) fail(doing);
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
