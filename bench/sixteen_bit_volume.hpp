// A float32 volume as the two 16-bit forms issue 22's benchmarks compare:
// binary16 (rounded) and uint16 codes (the volume's range on 0 .. 65535).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "ivol/binary16.hpp"

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

}  // namespace bench
