// Work split into parts run on threads, the caller's among them, so that
// neither an exception in a part nor a thread that cannot start (EAGAIN
// under an address-space or process limit) ends the process: a part whose
// thread cannot start runs on the caller's thread, and the first exception
// of any part is rethrown on the caller's once every part has ended.
#pragma once

#include <exception>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace ivol::detail {

// Runs work(0) .. work(parts - 1), each once, on up to `parts` threads.
template <class Work>
void run_parts(unsigned parts, Work&& work) {
  std::exception_ptr failure;
  std::mutex failure_mutex;
  auto guarded = [&](unsigned part) {
    try {
      work(part);
    } catch (...) {
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  unsigned started = 1;
  try {
    pool.reserve(parts > 1 ? parts - 1 : 0);
    for (; started < parts; ++started) pool.emplace_back(guarded, started);
  } catch (const std::system_error&) {  // no more threads: the caller runs the rest
  } catch (const std::bad_alloc&) {
  }
  guarded(0);
  for (unsigned part = started; part < parts; ++part) guarded(part);
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
}

}  // namespace ivol::detail
