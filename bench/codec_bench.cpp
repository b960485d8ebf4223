// Codec 3 (predicted 16-bit, spec §7.2) against codec 2 (zstd over byte
// planes) on the bricks of a real volume (issue 22), one core:
//
//   codec_bench VOLUME.f32 N [BRICK_LOG2 [ZSTD_LEVEL [ENTROPY]]]
//
// VOLUME.f32: N^3 float32, x fastest (peers_bench caches its reconstructions
// as such under WORK/cache). Each brick is encoded as binary16 and as uint16
// (the volume's range scaled to 0 .. 65535), with codec 3 and with codec 2 at
// zstd level ZSTD_LEVEL (default 3) for both, codec 3 with the entropy coder
// ENTROPY (auto: the library's default, coder 3 at zstd levels up to 3;
// smaller: coder 2 in bricks under 64³, the smaller of it and coder 1 where
// the encoder tries both; zstd: coder 1 only; tokens: coder 2 only, where
// the spec allows it; lanes: coder 3, coder 1 where Smaller would try it); prints bytes, and encode and decode (best of
// three passes) MB/s of 16-bit values per second of the thread's CPU time.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "ivol/predicted_codec.hpp"
#include "ivol/writer.hpp"
#include "sixteen_bit_volume.hpp"

namespace {

double since(double t) { return bench::thread_seconds() - t; }

void run(const char* label, const std::vector<std::uint16_t>& volume, std::uint32_t n, unsigned log2,
         ivol::ValueEncoding encoding, int zstd_level, ivol::PredictedOptions::Entropy entropy) {
  const std::vector<bench::Brick> bricks = bench::cut_bricks(volume, n, log2);
  const double mb = 2.0 * volume.size() / 1e6;
  std::uint64_t predicted_bytes = 0, planes_bytes = 0, best_bytes = 0;
  std::vector<std::vector<std::uint8_t>> payloads(bricks.size());
  auto t = bench::thread_seconds();
  for (std::size_t b = 0; b < bricks.size(); ++b) {
    ivol::PredictedOptions p;
    p.zstd_level = zstd_level;
    p.entropy = entropy;
    payloads[b] = ivol::encode_predicted(bricks[b].values.data(), bricks[b].dims, encoding, p);
    predicted_bytes += payloads[b].size();
  }
  const double encode3 = since(t);
  // Decoding is timed as the best of three passes over every brick (one
  // pass is a fraction of a second, and the machine is shared); the first
  // pass checks the round trip, outside the timing.
  std::vector<std::uint16_t> out;
  for (std::size_t b = 0; b < bricks.size(); ++b) {
    out.resize(bricks[b].values.size());
    ivol::decode_predicted(payloads[b].data(), payloads[b].size(), bricks[b].dims, out.data());
    if (out != bricks[b].values) std::fprintf(stderr, "codec_bench: brick %zu does not round-trip\n", b);
  }
  double decode3 = 0;
  for (int pass = 0; pass < 3; ++pass) {
    t = bench::thread_seconds();
    for (std::size_t b = 0; b < bricks.size(); ++b) {
      out.resize(bricks[b].values.size());
      ivol::decode_predicted(payloads[b].data(), payloads[b].size(), bricks[b].dims, out.data());
    }
    const double seconds = since(t);
    decode3 = pass == 0 || seconds < decode3 ? seconds : decode3;
  }
  ivol::WriteOptions w;
  w.zstd_level = zstd_level;
  t = bench::thread_seconds();
  for (std::size_t b = 0; b < bricks.size(); ++b) {
    const auto block = ivol::encode_block(ivol::Stream::Values, 0, 0, static_cast<std::uint32_t>(out.size()), 2,
                                          bricks[b].values.data(), w);
    planes_bytes += block.bytes.size();
    best_bytes += std::min(block.bytes.size(), payloads[b].size());
  }
  const double encode2 = since(t);
  std::printf(
      "%-9s %u^3 bricks of %u^3: codec 3 %llu bytes (%.1f %% of codec 2), encode %.0f MB/s, decode %.0f MB/s; "
      "codec 2 %llu bytes, encode %.0f MB/s; smaller of the two per brick %llu bytes (%.1f %%)\n",
      label, n, 1u << log2, static_cast<unsigned long long>(predicted_bytes), 100.0 * predicted_bytes / planes_bytes,
      mb / encode3, mb / decode3, static_cast<unsigned long long>(planes_bytes), mb / encode2,
      static_cast<unsigned long long>(best_bytes), 100.0 * best_bytes / planes_bytes);
}

}  // namespace

int main(int argc, char** argv) {
  bench::VolumeArgs args;
  if (!bench::read_volume_args(
          argc, argv, "codec_bench VOLUME.f32 N [BRICK_LOG2 [ZSTD_LEVEL [auto|smaller|zstd|tokens|lanes]]]", args))
    return 2;
  const std::uint32_t n = args.n;
  const unsigned log2 = args.log2;
  const bench::SixteenBitVolume& volume = args.volume;
  const int zstd_level = argc > 4 ? std::stoi(argv[4]) : 3;
  const std::string coder = argc > 5 ? argv[5] : "auto";
  using Entropy = ivol::PredictedOptions::Entropy;
  const Entropy entropy = coder == "zstd"      ? Entropy::ZstdPlanes
                          : coder == "tokens"  ? Entropy::Tokens
                          : coder == "lanes"   ? Entropy::Lanes
                          : coder == "smaller" ? Entropy::Smaller
                                               : Entropy::Auto;
  run("binary16", volume.binary16, n, log2, ivol::ValueEncoding::Binary16, zstd_level, entropy);
  run("uint16", volume.codes, n, log2, ivol::ValueEncoding::UInt16, zstd_level, entropy);
  return 0;
}
