// Work split over threads for the native CPU paths (fdk_native_*.cpp).
// Internal to recon.
#pragma once

#include <system_error>
#include <thread>
#include <vector>

namespace ivol::recon::detail {

// Runs work(t) for t = 0 .. threads − 1, the last (and any the system
// would not start a thread for) on the calling thread.
template <class Work>
void on_threads(unsigned threads, const Work& work) {
  std::vector<std::thread> pool;
  unsigned started = 0;
  try {
    for (; started + 1 < threads; ++started) pool.emplace_back([&work, started] { work(started); });
  } catch (const std::system_error&) {
  }
  for (unsigned t = started; t < threads; ++t) work(t);
  for (std::thread& thread : pool) thread.join();
}

}  // namespace ivol::recon::detail
