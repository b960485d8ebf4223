// Size arithmetic and allocation for the converters. Dimensions come from
// input files and options that may be hostile (2^31 per side, an empty file
// claiming 2^64 bytes), so every product of sizes is checked for overflow,
// every large buffer is weighed against the memory budget before it is
// allocated, and an allocation that still fails becomes an ivol::Error
// naming what was being allocated, not a bare std::bad_alloc.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <new>
#include <stdexcept>
#include <string>

#include "dense_volume.hpp"
#include "ivol/error.hpp"

namespace ivol::convert {

// What a conversion may hold when --memory is not given.
constexpr std::uint64_t kDefaultMemoryBytes = std::uint64_t{2048} << 20;

inline std::uint64_t memory_budget(std::uint64_t bytes) { return bytes ? bytes : kDefaultMemoryBytes; }

// The decoded-block cache of the Reader a conversion out of .ivol reads
// with (ReaderOptions::cache_bytes): a quarter of --memory, at most the
// Reader's default 256 MiB. It is held besides --memory (README, "What a
// conversion may hold").
inline std::uint64_t export_cache_bytes(std::uint64_t memory_bytes) {
  return std::min<std::uint64_t>(std::uint64_t{256} << 20, memory_budget(memory_bytes) / 4);
}

inline std::string dims_text(const Dims& dims) {
  return std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
}

inline std::string mib_text(std::uint64_t bytes) {
  return std::to_string((bytes + (std::uint64_t{1} << 20) - 1) >> 20) + " MiB";
}

// The same for sizes past 2^64 (a slice of a valid file of 2^31 voxels a
// side, as float32, is 2^64 bytes).
inline std::string mib_text(double bytes) {
  char text[48];
  std::snprintf(text, sizeof text, "%.0f MiB", std::ceil(bytes / 1048576.0));
  return text;
}

// a * b, or Error(LimitExceeded) naming `what` and both factors.
inline std::uint64_t checked_mul(std::uint64_t a, std::uint64_t b, const std::string& what) {
  std::uint64_t product = 0;
  if (__builtin_mul_overflow(a, b, &product))
    throw Error(ErrorClass::LimitExceeded, what + ": " + std::to_string(a) + " x " + std::to_string(b) +
                                               " exceeds 2^64 (the sizes are impossible)");
  return product;
}

inline std::uint64_t checked_add(std::uint64_t a, std::uint64_t b, const std::string& what) {
  std::uint64_t sum = 0;
  if (__builtin_add_overflow(a, b, &sum))
    throw Error(ErrorClass::LimitExceeded, what + ": " + std::to_string(a) + " + " + std::to_string(b) +
                                               " exceeds 2^64 (the sizes are impossible)");
  return sum;
}

// Voxels of one z slice, and of the volume.
inline std::uint64_t slice_voxels(const Dims& dims, const std::string& what) {
  return checked_mul(dims[0], dims[1],
                     what + " (voxels of a " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + " slice)");
}
inline std::uint64_t volume_voxels(const Dims& dims, const std::string& what) {
  return checked_mul(slice_voxels(dims, what), dims[2], what + " (voxels of " + dims_text(dims) + ")");
}
// Bytes of `slices` slices of samples of `type`.
inline std::uint64_t slab_bytes(const Dims& dims, std::uint64_t slices, SampleType type, const std::string& what) {
  const std::uint64_t voxels = checked_mul(slice_voxels(dims, what), slices,
                                           what + " (voxels of " + std::to_string(slices) + " slices of " +
                                               std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + ")");
  return checked_mul(voxels, sample_size(type), what + " (bytes of " + sample_type_name(type) + " samples)");
}

// The --memory option (in MiB) under which `bytes` fit.
inline std::string memory_option_for(std::uint64_t bytes) {
  return "--memory " + std::to_string((bytes + (std::uint64_t{1} << 20) - 1) >> 20);
}

// Refuses `bytes` above `budget` before anything is allocated; `what` says
// what needs them ("one slice of 16384x16384 u8 as float32"). Every caller's
// need is independent of the budget, so the --memory named allows it.
inline void require_within_budget(std::uint64_t bytes, std::uint64_t budget, const std::string& what) {
  if (bytes > budget)
    throw Error(ErrorClass::LimitExceeded, what + " needs " + mib_text(bytes) + ", more than the " + mib_text(budget) +
                                               " this conversion may hold (" + memory_option_for(bytes) +
                                               " allows it)");
}

// The same for a size computed in floating point, for products that may
// pass 2^64: refused with the true figure rather than "exceeds 2^64".
inline void require_within_budget(double bytes, std::uint64_t budget, const std::string& what) {
  if (bytes > static_cast<double>(budget))
    throw Error(ErrorClass::LimitExceeded,
                what + " needs " + mib_text(bytes) + ", more than the " + mib_text(budget) +
                    " this conversion may hold" +
                    (bytes < 1.8e19 ? " (" + memory_option_for(static_cast<std::uint64_t>(bytes)) + " allows it)"
                                    : std::string(" (more than any memory holds)")));
}

// v.resize(count), turning an allocation failure (or a size past the address
// space) into Error(LimitExceeded) naming `what` and the bytes asked for.
template <typename Vector>
void checked_resize(Vector& v, std::uint64_t count, const std::string& what) {
  const std::uint64_t bytes = checked_mul(count, sizeof(typename Vector::value_type), what);
  try {
    if (count > v.max_size()) throw std::length_error("");
    v.resize(static_cast<std::size_t>(count));
  } catch (const std::bad_alloc&) {
    throw Error(ErrorClass::LimitExceeded, what + ": cannot allocate " + mib_text(bytes) + " (out of memory)");
  } catch (const std::length_error&) {
    throw Error(ErrorClass::LimitExceeded, what + ": cannot allocate " + mib_text(bytes) + " (out of memory)");
  }
}

}  // namespace ivol::convert
