// When may the bricked writer skip its trial of codec 2 (zstd over the byte
// planes) on a 16-bit brick? The trial was a tenth of a binary16
// conversion's CPU time, and codec 2 wins only bricks where prediction does
// not pay. This study codes every brick of a real volume as the writer
// does at the default zstd level 3 (codec 3; codec 2 tried at level 1 and
// made again at 3 where it wins; codec 6 where codec 2 comes within 5 % of
// codec 3 and the best spends over a quarter of the bits) and prints, for
// cheaper stand-ins for the trial (the byte planes' order-0 entropy, zstd
// on a quarter of the brick, zstd at levels -1, -3, -5) and margins, the
// share of trials left and the bytes against trying every brick:
//
//   plane_trial_study VOLUME.f32 N [BRICK_LOG2]
//
// VOLUME.f32: N^3 float32, x fastest (as codec_bench reads it), coded as
// binary16 and as uint16. With PLANE_TRIAL_CSV=FILE every brick's sizes are
// appended to FILE (label, brick edge, voxels, codec 3, codec 2 at levels 1
// and 3, codec 6, order-0 estimate, the writer's choice, zstd -5), for
// rules the printout does not try (the writer's came from those files).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ivol/bricked_writer.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/top_byte_codec.hpp"
#include "ivol/writer.hpp"
#include "sixteen_bit_volume.hpp"

namespace {

// The order-0 entropy of the low and the high bytes, in bytes, from every
// fourth value, as the writer estimates it (bricked_writer.cpp).
double plane_entropy_bytes(const std::vector<std::uint16_t>& v) {
  std::array<std::uint32_t, 256> low{}, high{};
  std::size_t sampled = 0;
  for (std::size_t i = 0; i < v.size(); i += 4, ++sampled) ++low[v[i] & 0xFF], ++high[v[i] >> 8];
  double bits = 0;
  for (const auto* h : {&low, &high})
    for (const std::uint32_t c : *h)
      if (c) bits += c * std::log2(static_cast<double>(sampled) / c);
  return bits / 8 * (static_cast<double>(v.size()) / static_cast<double>(sampled));
}

// zstd over the two byte planes of v[0 .. count), as codec 2 makes them
// (each plane ends a zstd block), at `level`: its bytes and CPU seconds.
std::size_t planes_bytes(const std::uint16_t* v, std::size_t count, int level, double& seconds) {
  const double t = bench::thread_seconds();
  ivol::WriteOptions w;
  w.zstd_level = level;
  const std::size_t size =
      ivol::encode_block(ivol::Stream::Values, 0, 0, static_cast<std::uint32_t>(count), 2, v, w).bytes.size();
  seconds += bench::thread_seconds() - t;
  return size;
}

struct BrickResult {
  std::size_t n, predicted, level1, level3, top_byte;
  double entropy;                            // order-0 estimate
  std::size_t quarter, fast1, fast3, fast5;  // cheaper trials: a quarter at level 1 (times 4), levels −1, −3, −5
};

// The writer's choice (bricked_writer.cpp) given the trial `trial` that
// stands in for codec 2 at level 1: codec 3; codec 2 where it wins; codec 6
// where the trial comes within 5 % of codec 3; stored at most.
std::size_t writer_choice(const BrickResult& r, std::size_t trial) {
  std::size_t best = r.predicted;
  if (trial < r.predicted) best = std::min({r.predicted, r.level1, r.level3});
  if (100 * trial < 105 * r.predicted && best > 2 * r.n / 4) best = std::min(best, r.top_byte);
  return std::min(best, 2 * r.n);
}

struct Seconds {
  double predicted = 0, level1 = 0, level3 = 0, quarter = 0, fast1 = 0, fast3 = 0, fast5 = 0;
};

BrickResult code_brick(const std::vector<std::uint16_t>& v, const ivol::BrickDims& e, ivol::ValueEncoding encoding,
                       Seconds& s) {
  const std::size_t n = v.size();
  BrickResult r{};
  r.n = n;
  ivol::PredictedOptions p;
  p.zstd_level = ivol::residual_zstd_level(3);
  double t = bench::thread_seconds();
  r.predicted = ivol::encode_predicted(v.data(), e, encoding, p).size();
  s.predicted += bench::thread_seconds() - t;
  r.level1 = planes_bytes(v.data(), n, 1, s.level1);
  r.level3 = planes_bytes(v.data(), n, 3, s.level3);
  r.quarter = 4 * planes_bytes(v.data(), n / 4, 1, s.quarter);
  r.fast1 = planes_bytes(v.data(), n, -1, s.fast1);
  r.fast3 = planes_bytes(v.data(), n, -3, s.fast3);
  r.fast5 = planes_bytes(v.data(), n, -5, s.fast5);
  std::vector<std::uint8_t> bytes(2 * n);
  for (std::size_t i = 0; i < n; ++i)
    bytes[2 * i] = v[i] & 0xFF, bytes[2 * i + 1] = static_cast<std::uint8_t>(v[i] >> 8);
  const auto top = ivol::encode_top_byte(bytes.data(), e, 2, 2 * n + 1);
  r.top_byte = top.empty() ? 2 * n + 1 : top.size();
  r.entropy = plane_entropy_bytes(v);
  return r;
}

void study(const char* label, const std::vector<std::uint16_t>& volume, std::uint32_t n, unsigned log2,
           ivol::ValueEncoding encoding) {
  const std::uint32_t b = 1u << log2;
  std::vector<BrickResult> results;
  Seconds s;
  for (const bench::Brick& brick : bench::cut_bricks(volume, n, log2))
    results.push_back(code_brick(brick.values, brick.dims, encoding, s));
  std::uint64_t full = 0;
  std::size_t won = 0;
  for (const auto& r : results) {
    const std::size_t best = writer_choice(r, r.level1);
    full += best;
    won += best < r.predicted;
  }
  std::printf(
      "%-8s bricks %u^3: %zu bricks, codec 2 or 6 won %zu; %llu bytes with every trial; CPU s: codec 3 "
      "%.3f, trial at level 1 %.3f (3: %.3f), a quarter %.3f, level -1 %.3f, -3 %.3f, -5 %.3f\n",
      label, b, results.size(), won, static_cast<unsigned long long>(full), s.predicted, s.level1, s.level3, s.quarter,
      s.fast1, s.fast3, s.fast5);
  if (const char* csv = std::getenv("PLANE_TRIAL_CSV")) {
    if (FILE* f = std::fopen(csv, "a")) {
      for (const auto& r : results)
        std::fprintf(f, "%s,%u,%zu,%zu,%zu,%zu,%zu,%.1f,%zu,%zu\n", label, b, r.n, r.predicted, r.level1, r.level3,
                     r.top_byte, r.entropy, writer_choice(r, r.level1), r.fast5);
      std::fclose(f);
    }
  }
  struct Rule {
    const char* name;
    std::size_t BrickResult::*cheap;  // nullptr: the order-0 estimate
    double cost;                      // the cheap trial's seconds
  };
  for (const Rule& rule :
       {Rule{"entropy", nullptr, 0}, Rule{"quarter", &BrickResult::quarter, s.quarter},
        Rule{"level -1", &BrickResult::fast1, s.fast1}, Rule{"level -3", &BrickResult::fast3, s.fast3},
        Rule{"level -5", &BrickResult::fast5, s.fast5}})
    for (const double margin : {0.0, 0.05, 0.10, 0.20}) {
      // The level-1 trial only where the cheap one comes within the margin of codec 3.
      std::uint64_t bytes = 0;
      std::size_t trials = 0;
      for (const auto& r : results) {
        const double cheap = rule.cheap ? static_cast<double>(r.*rule.cheap) : r.entropy;
        const bool trial = cheap < (1 + margin) * static_cast<double>(r.predicted);
        trials += trial;
        bytes += trial ? writer_choice(r, r.level1) : r.predicted;
      }
      const double fraction = static_cast<double>(trials) / results.size();
      std::printf("  %-8s margin %.2f: level-1 trials %5.1f %%, trial CPU %5.1f %% of now, bytes %+.4f %%\n", rule.name,
                  margin, 100 * fraction, 100 * (rule.cost + fraction * s.level1) / s.level1,
                  100.0 * (static_cast<double>(bytes) / full - 1));
    }
}

}  // namespace

int main(int argc, char** argv) {
  bench::VolumeArgs args;
  if (!bench::read_volume_args(argc, argv, "plane_trial_study VOLUME.f32 N [BRICK_LOG2]", args)) return 2;
  const std::uint32_t n = args.n;
  const unsigned log2 = args.log2;
  const bench::SixteenBitVolume& volume = args.volume;
  study("binary16", volume.binary16, n, log2, ivol::ValueEncoding::Binary16);
  study("uint16", volume.codes, n, log2, ivol::ValueEncoding::UInt16);
  return 0;
}
