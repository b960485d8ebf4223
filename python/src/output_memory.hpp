// Memory for the output of a large read, handed to numpy as the array's own.
//
// numpy asks for transparent huge pages (MADV_HUGEPAGE) for every array of
// 4 MiB or more. Where THP's defrag policy is "madvise" (the kernel's
// default), the first touch of such memory may stall in direct compaction:
// the same whole read of the 512³ bench volume took 0.44 s or 1.2 s from one
// run to the next (bench/RESULTS.md, "The whole read's output memory"). The
// memory here follows the kernel's default policy instead (huge pages only
// where they come without compaction) and is faulted in before the read on
// several threads at once (MADV_POPULATE_WRITE, Linux 5.14; on an older
// kernel the read's own writes fault it in, as before).
#pragma once

#include <sys/mman.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <new>
#include <thread>
#include <vector>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23
#endif

namespace ivol_python {

// Reads smaller than this take numpy's own allocation: their page faults
// are a small share of the read, and mmap's system calls are not.
constexpr std::size_t kMappedOutputBytes = std::size_t{32} << 20;

// `bytes` of zeroed, writable memory, resident on return where the kernel
// can populate it; release with unmap_output. Throws std::bad_alloc when
// the memory cannot be had (an address-space limit, or no memory to
// populate it with), before anything is read.
inline void* map_output(std::size_t bytes) {
  void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  const std::size_t page = 4096;
  const std::size_t slice = std::size_t{16} << 20;  // a thread's share is at least this
  const auto hardware = std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
  const auto threads = static_cast<unsigned>(std::max<std::size_t>(1, std::min<std::size_t>(hardware, bytes / slice)));
  const std::size_t share = (bytes / threads + page - 1) / page * page;
  std::vector<int> errors(threads, 0);
  auto populate = [&](unsigned t) {
    const std::size_t begin = std::min(bytes, t * share), end = std::min(bytes, begin + share);
    if (begin < end && madvise(static_cast<char*>(p) + begin, end - begin, MADV_POPULATE_WRITE) != 0) errors[t] = errno;
  };
  std::vector<std::thread> pool;
  try {
    for (unsigned t = 1; t < threads; ++t) pool.emplace_back(populate, t);
  } catch (const std::system_error&) {
    // No more threads: the pages of those not started fault in during the read.
  }
  populate(0);
  for (std::thread& t : pool) t.join();
  for (const int e : errors)
    if (e == ENOMEM || e == EFAULT) {  // EINVAL: a kernel before 5.14
      munmap(p, bytes);
      throw std::bad_alloc();
    }
  return p;
}

inline void unmap_output(void* p, std::size_t bytes) { munmap(p, bytes); }

}  // namespace ivol_python
