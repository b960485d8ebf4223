// A float32 volume as the two 16-bit forms issue 22's benchmarks compare:
// binary16 (rounded) and uint16 codes (the volume's range on 0 .. 65535);
// and what the codec benches share besides: the volume cut into bricks, a
// thread's CPU clock.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "ivol/binary16.hpp"
#include "ivol/predicted_codec.hpp"

namespace bench {

struct SixteenBitVolume {
  std::vector<std::uint16_t> binary16;
  std::vector<std::uint16_t> codes;
};

// Reads n^3 float32 (x fastest) from `path`; throws std::runtime_error
// naming the file when it holds fewer.
inline SixteenBitVolume read_sixteen_bit(const std::string& path, std::uint32_t n) {
  std::vector<float> f(std::size_t{n} * n * n);
  std::ifstream in(path, std::ios::binary);
  if (!in.read(reinterpret_cast<char*>(f.data()), static_cast<std::streamsize>(f.size() * 4)))
    throw std::runtime_error("cannot read " + std::to_string(f.size()) + " float32 from " + path);
  SixteenBitVolume v{std::vector<std::uint16_t>(f.size()), std::vector<std::uint16_t>(f.size())};
  const auto [lo, hi] = std::minmax_element(f.begin(), f.end());
  for (std::size_t i = 0; i < f.size(); ++i) {
    v.binary16[i] = ivol::float_to_binary16(f[i]);
    v.codes[i] = static_cast<std::uint16_t>(std::lround((f[i] - *lo) / (*hi - *lo) * 65535.0));
  }
  return v;
}

// The VOLUME.f32 N [BRICK_LOG2 ...] at the start of a codec bench's
// arguments, and the volume read: false, after printing `usage` or what
// failed, where they do not serve.
struct VolumeArgs {
  std::uint32_t n = 0;
  unsigned log2 = 5;
  SixteenBitVolume volume;
};
inline bool read_volume_args(int argc, char** argv, const char* usage, VolumeArgs& out) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s\n", usage);
    return false;
  }
  try {
    out.n = static_cast<std::uint32_t>(std::stoul(argv[2]));
    out.log2 = argc > 3 ? static_cast<unsigned>(std::stoul(argv[3])) : 5;
    out.volume = read_sixteen_bit(argv[1], out.n);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return false;
  }
  return true;
}

struct Brick {
  ivol::BrickDims dims;
  std::vector<std::uint16_t> values;
};

// The n^3 volume v in bricks of 2^log2 (smaller at the far faces), in
// brick order, each brick's values in raster order.
inline std::vector<Brick> cut_bricks(const std::vector<std::uint16_t>& v, std::uint32_t n, unsigned log2) {
  const std::uint32_t b = 1u << log2;
  std::vector<Brick> out;
  for (std::uint32_t z0 = 0; z0 < n; z0 += b)
    for (std::uint32_t y0 = 0; y0 < n; y0 += b)
      for (std::uint32_t x0 = 0; x0 < n; x0 += b) {
        Brick brick;
        brick.dims = {std::min(b, n - x0), std::min(b, n - y0), std::min(b, n - z0)};
        for (std::uint32_t z = z0; z < z0 + brick.dims[2]; ++z)
          for (std::uint32_t y = y0; y < y0 + brick.dims[1]; ++y)
            for (std::uint32_t x = x0; x < x0 + brick.dims[0]; ++x)
              brick.values.push_back(v[(std::size_t{z} * n + y) * n + x]);
        out.push_back(std::move(brick));
      }
  return out;
}

// The calling thread's CPU seconds, not the wall clock: on a machine shared
// with other work the wall clock measures the neighbours; one thread's CPU
// seconds are what "MB/s per core" means.
inline double thread_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace bench
