#include "signal_cleanup.hpp"

#include <dirent.h>
#include <pthread.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ctime>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace ivol::cli {
namespace {

// The temporary files of the outputs, removed when a signal ends the run.
// Written by the command's thread, read by the signal thread.
struct TemporaryOutputs {
  struct Output {
    std::string directory;
    std::string prefix;  // ".<name>.tmp-"
  };
  std::mutex mutex;
  std::vector<Output> outputs;
  std::time_t since = std::time(nullptr) - 1;  // whole seconds: never miss a file of this run

  void remove() {
    std::lock_guard<std::mutex> lock(mutex);
    for (const Output& output : outputs) {
      DIR* dir = ::opendir(output.directory.c_str());
      if (dir == nullptr) continue;
      while (const dirent* entry = ::readdir(dir)) {
        const std::string name = entry->d_name;
        if (name.compare(0, output.prefix.size(), output.prefix) != 0) continue;
        const std::string path = output.directory + "/" + name;
        struct stat st {};
        if (::stat(path.c_str(), &st) == 0 && st.st_mtime >= since) ::unlink(path.c_str());
      }
      ::closedir(dir);
    }
  }
};

TemporaryOutputs& temporary_outputs() {
  static TemporaryOutputs outputs;
  return outputs;
}

sigset_t ending_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  return signals;
}

}  // namespace

void start_signal_cleanup() {
  temporary_outputs();  // its clock starts now
  const sigset_t signals = ending_signals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  try {
    std::thread([signals] {
      int received = 0;
      if (sigwait(&signals, &received) != 0) return;
      temporary_outputs().remove();
      // End by the signal itself: its default action, unblocked in this
      // thread, kills the process as it would have without this thread.
      ::signal(received, SIG_DFL);
      sigset_t one;
      sigemptyset(&one);
      sigaddset(&one, received);
      pthread_sigmask(SIG_UNBLOCK, &one, nullptr);
      ::raise(received);
      ::_exit(128 + received);
    }).detach();
  } catch (const std::system_error&) {
    // No thread to be had (a process or address-space limit): the signals'
    // default actions again; a killed run then leaves its temporary output,
    // as after SIGKILL, and the next writer of that name removes it.
    pthread_sigmask(SIG_UNBLOCK, &signals, nullptr);
  }
}

void remove_temporaries_on_signal(const std::string& output) {
  TemporaryOutputs& t = temporary_outputs();
  std::lock_guard<std::mutex> lock(t.mutex);
  const std::size_t slash = output.find_last_of('/');
  t.outputs.push_back({slash == std::string::npos ? "." : slash == 0 ? "/" : output.substr(0, slash),
                       "." + (slash == std::string::npos ? output : output.substr(slash + 1)) + ".tmp-"});
}

}  // namespace ivol::cli
