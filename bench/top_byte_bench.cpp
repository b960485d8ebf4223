// Codec 6 (the top byte in context, spec §7.4) on every brick of a real
// volume, one core (issue 22):
//
//   top_byte_bench VOLUME.f32 N [BRICK] [f16|u16|f32]
//
// VOLUME.f32: N^3 float32, x fastest. Each brick of BRICK^3 (default 32) is
// coded as codec 6 with the library's choices, whether or not the writer
// would keep codec 6 for it (where the payload would pass the spec's limit
// the brick is left out), then all of them are decoded five times; prints
// their bytes and the best pass's MB/s of values per second of the
// thread's CPU time, encoding and decoding, and checks every bit.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "ivol/top_byte_codec.hpp"
#include "sixteen_bit_volume.hpp"

namespace {

double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: top_byte_bench VOLUME.f32 N [BRICK] [f16|u16|f32]\n");
    return 1;
  }
  const auto n = static_cast<unsigned>(std::atoi(argv[2]));
  const unsigned b = argc > 3 ? static_cast<unsigned>(std::atoi(argv[3])) : 32;
  const std::string kind = argc > 4 ? argv[4] : "f16";
  if (b == 0 || n % b != 0 || (kind != "f16" && kind != "u16" && kind != "f32")) {
    std::fprintf(stderr, "top_byte_bench: BRICK must divide N; the kind is f16, u16 or f32\n");
    return 1;
  }
  const unsigned w = kind == "f32" ? 4 : 2;
  std::vector<std::uint8_t> bytes;
  if (w == 4) {
    bytes.resize(std::size_t{n} * n * n * 4);
    FILE* f = std::fopen(argv[1], "rb");
    if (!f || std::fread(bytes.data(), 1, bytes.size(), f) != bytes.size()) {
      std::fprintf(stderr, "top_byte_bench: cannot read %zu bytes from %s\n", bytes.size(), argv[1]);
      return 1;
    }
    std::fclose(f);
  } else {
    const bench::SixteenBitVolume volume = bench::read_sixteen_bit(argv[1], n);
    const std::vector<std::uint16_t>& v = kind == "u16" ? volume.codes : volume.binary16;
    bytes.resize(2 * v.size());
    for (std::size_t i = 0; i < v.size(); ++i)
      bytes[2 * i] = static_cast<std::uint8_t>(v[i]), bytes[2 * i + 1] = static_cast<std::uint8_t>(v[i] >> 8);
  }
  const ivol::BrickDims dims{b, b, b};
  std::vector<std::vector<std::uint8_t>> bricks;
  for (unsigned z0 = 0; z0 < n; z0 += b)
    for (unsigned y0 = 0; y0 < n; y0 += b)
      for (unsigned x0 = 0; x0 < n; x0 += b) {
        std::vector<std::uint8_t> brick;
        for (unsigned z = z0; z < z0 + b; ++z)
          for (unsigned y = y0; y < y0 + b; ++y) {
            const std::size_t at = ((std::size_t{z} * n + y) * n + x0) * w;
            brick.insert(brick.end(), bytes.begin() + at, bytes.begin() + at + std::size_t{b} * w);
          }
        bricks.push_back(std::move(brick));
      }
  std::vector<std::vector<std::uint8_t>> coded(bricks.size()), kept;
  double encode = 1e300;
  for (int pass = 0; pass < 3; ++pass) {
    const double t = cpu_seconds();
    for (std::size_t i = 0; i < bricks.size(); ++i)
      coded[i] = ivol::encode_top_byte(bricks[i].data(), dims, w, SIZE_MAX);
    encode = std::min(encode, cpu_seconds() - t);
  }
  std::vector<std::size_t> which;
  std::size_t payload = 0;
  for (std::size_t i = 0; i < coded.size(); ++i)
    if (!coded[i].empty()) which.push_back(i), payload += coded[i].size();
  std::vector<std::uint8_t> back(bricks[0].size());
  double decode = 1e300;
  for (int pass = 0; pass < 5; ++pass) {
    const double t = cpu_seconds();
    for (const std::size_t i : which) ivol::decode_top_byte(coded[i].data(), coded[i].size(), dims, w, back.data());
    decode = std::min(decode, cpu_seconds() - t);
  }
  for (const std::size_t i : which) {
    ivol::decode_top_byte(coded[i].data(), coded[i].size(), dims, w, back.data());
    if (back != bricks[i]) {
      std::fprintf(stderr, "top_byte_bench: brick %zu does not come back bit for bit\n", i);
      return 1;
    }
  }
  const double all_mb = static_cast<double>(bricks.size()) * bricks[0].size() / 1e6;
  const double kept_mb = static_cast<double>(which.size()) * bricks[0].size() / 1e6;
  std::printf("%s %s, bricks of %u^3: %zu of %zu bricks as codec 6, %zu bytes; encode %.0f MB/s, decode %.0f MB/s\n",
              argv[1], kind.c_str(), b, which.size(), bricks.size(), payload, all_mb / encode, kept_mb / decode);
  return 0;
}
