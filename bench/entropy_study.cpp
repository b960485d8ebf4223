// What an entropy coder with contexts would save over codec 3's zstd byte
// planes (issue 22, item 1), measured on codec 3's own residuals:
//
//   entropy_study VOLUME.f32 N [BRICK_LOG2]
//
// VOLUME.f32: N^3 float32, x fastest. Each brick is encoded by codec 3
// exactly as the writer's codec 3 attempt does (encode_predicted: the best
// of Lorenzo and the two least-squares fits); the residuals are read back
// from its zstd frame (spec §7.2: low bytes, then high bytes), so every
// model below codes the same residuals the file holds. Printed, in bytes
// summed over the bricks, as binary16 and as uint16 (the volume's range on
// 0 .. 65535), beside codec 3's payloads:
//   order-0    the residuals' 16-bit order-0 entropy per brick (a static
//              coder's floor without the cost of its table);
//   contexts   each residual z as a token (z < 2 itself, else its bit length
//              b and the bit after its leading one) in one of 12 contexts
//              from the bit lengths of the residuals before it along x, y
//              and z (ctx = (2 bl + bu + bb + 1) / 3), the b - 2 bits below
//              sent as they are; static per brick, no table;
//   adaptive   the same tokens and contexts with counts that learn within
//              the brick (Krichevsky-Trofimov: every count starts at 1/2),
//              what an adaptive arithmetic coder would reach, learning cost
//              included and nothing stored besides.
//   split      a coder, not an entropy: the same tokens, each context's
//              in a part of its own, then the bits below packed LSB first,
//              all in one zstd frame at level 3 with each part ending a zstd
//              block (a Huffman table per context: what zstd can do with the
//              contexts), plus codec 3's 24-byte header and 4 bytes a
//              context for the parts' lengths.
//   coder 2    codec 3's entropy coder 2 as the library writes it (rANS over
//              the same tokens in 12 adaptive contexts from the rows before,
//              spec §7.2.1): real payloads, header included;
//   static 12  what a static coder with stored tables would write (issue 22,
//              item 4: a coder whose lanes decode a row's voxels side by
//              side needs tables that do not change within the brick):
//              coder 2's tokens and row contexts, each context's counts
//              normalised to 2^12 (every token seen at least 1), the tokens'
//              ideal cost under those frequencies, the bits below, a table
//              per brick (a bit for a context not used; else a bit a token
//              for which are present, and each present frequency in an
//              Elias gamma code), 8 rANS states of 4 bytes and codec 3's
//              24-byte header.
// order-0, contexts and adaptive are entropies, not a coder: a real one adds
// a few bytes a brick.
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "ivol/predicted_codec.hpp"
#include "sixteen_bit_volume.hpp"

namespace {

constexpr int kContexts = 12;
constexpr int kTokens = 32;

int bit_length(unsigned z) { return z == 0 ? 0 : 32 - __builtin_clz(z); }

// Token 0 or 1 for z < 2; else 2b − 2 + the bit after the leading one (2 .. 31).
int token(unsigned z, int b) { return z < 2 ? static_cast<int>(z) : 2 * b - 2 + static_cast<int>((z >> (b - 2)) & 1); }

double entropy_bits(const double* counts, int size) {
  double n = 0, h = 0;
  for (int i = 0; i < size; ++i) n += counts[i];
  for (int i = 0; i < size; ++i)
    if (counts[i] > 0) h -= counts[i] * std::log2(counts[i] / n);
  return h;
}

struct Sizes {
  double codec3 = 0, order0 = 0, static_ctx = 0, adaptive = 0, split = 0, coder2 = 0, static12 = 0;
};

// Coder 2's context of a voxel from the bit lengths of the rows before it
// (spec §7.2.1): s = 2 up(x) + back(x) + up(x − 1) + up(x + 1), 0 outside
// the brick, context min(11, (s + 2) / 5).
int row_context(const std::vector<int>& lengths, const ivol::BrickDims& d, std::uint32_t x, std::uint32_t y,
                std::uint32_t z, std::size_t i) {
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  auto up = [&](std::int64_t dx) {
    const std::int64_t xx = static_cast<std::int64_t>(x) + dx;
    return y > 0 && xx >= 0 && xx < static_cast<std::int64_t>(d[0]) ? lengths[i - sy + static_cast<std::size_t>(dx)]
                                                                    : 0;
  };
  const int back = z > 0 ? lengths[i - sz] : 0;
  return std::min(kContexts - 1, (2 * up(0) + back + up(-1) + up(1) + 2) / 5);
}

// A brick's tokens under static 12-bit tables, and the tables (above).
double static_table_bytes(const std::vector<unsigned>& z, const ivol::BrickDims& d) {
  std::vector<int> lengths(z.size());
  for (std::size_t i = 0; i < z.size(); ++i) lengths[i] = bit_length(z[i]);
  std::vector<std::uint32_t> counts(kContexts * kTokens, 0);
  double raw_bits = 0;
  std::size_t i = 0;
  for (std::uint32_t zz = 0; zz < d[2]; ++zz)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const int b = lengths[i];
        counts[row_context(lengths, d, x, y, zz, i) * kTokens + token(z[i], b)] += 1;
        raw_bits += b > 2 ? b - 2 : 0;
      }
  double bits = raw_bits;
  for (int c = 0; c < kContexts; ++c) {
    const std::uint32_t* n = counts.data() + c * kTokens;
    std::uint64_t total = 0;
    for (int t = 0; t < kTokens; ++t) total += n[t];
    bits += 1;  // used or not
    if (total == 0) continue;
    // Normalised to 2^12, each present token at least 1, the rest to the largest.
    std::uint32_t f[kTokens] = {};
    std::int64_t sum = 0;
    int largest = 0;
    for (int t = 0; t < kTokens; ++t) {
      if (!n[t]) continue;
      f[t] = std::max<std::uint32_t>(1, static_cast<std::uint32_t>(4096.0 * n[t] / static_cast<double>(total)));
      sum += f[t];
      if (n[t] > n[largest]) largest = t;
    }
    f[largest] = static_cast<std::uint32_t>(static_cast<std::int64_t>(f[largest]) + 4096 - sum);
    bits += kTokens;  // which tokens are present
    for (int t = 0; t < kTokens; ++t)
      if (n[t]) {
        bits += 2 * std::floor(std::log2(f[t])) + 1;  // Elias gamma
        bits -= static_cast<double>(n[t]) * std::log2(f[t] / 4096.0);
      }
  }
  return bits / 8 + 8 * 4 + static_cast<double>(ivol::kPredictedHeaderSize);
}

// One zstd frame of `parts`, each ending a zstd block; its size.
std::size_t frame_of_parts(const std::vector<std::vector<std::uint8_t>>& parts) {
  thread_local std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
  ZSTD_CCtx_reset(context.get(), ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_compressionLevel, 3);
  std::size_t total = 0;
  for (const auto& p : parts) total += p.size();
  ZSTD_CCtx_setPledgedSrcSize(context.get(), total);
  std::vector<std::uint8_t> out(ZSTD_compressBound(total) + 64 * parts.size());
  ZSTD_outBuffer o{out.data(), out.size(), 0};
  for (std::size_t k = 0; k < parts.size(); ++k) {
    ZSTD_inBuffer in{parts[k].data(), parts[k].size(), 0};
    for (;;) {
      const std::size_t left =
          ZSTD_compressStream2(context.get(), &o, &in, k + 1 == parts.size() ? ZSTD_e_end : ZSTD_e_flush);
      if (ZSTD_isError(left)) throw std::runtime_error(std::string("entropy_study: ") + ZSTD_getErrorName(left));
      if (left == 0) break;
    }
  }
  return o.pos;
}

// The residuals of one brick, as codec 3 writes them.
std::vector<unsigned> residuals(const std::vector<std::uint16_t>& brick, const ivol::BrickDims& d,
                                ivol::ValueEncoding encoding, Sizes& s) {
  ivol::PredictedOptions planes_only;
  planes_only.entropy = ivol::PredictedOptions::Entropy::ZstdPlanes;
  const std::vector<std::uint8_t> payload = ivol::encode_predicted(brick.data(), d, encoding, planes_only);
  s.codec3 += static_cast<double>(payload.size());
  ivol::PredictedOptions tokens_only;
  tokens_only.entropy = ivol::PredictedOptions::Entropy::Tokens;
  s.coder2 += static_cast<double>(ivol::encode_predicted(brick.data(), d, encoding, tokens_only).size());
  const std::size_t n = brick.size();
  std::vector<std::uint8_t> planes(2 * n);
  const std::size_t got = ZSTD_decompress(planes.data(), planes.size(), payload.data() + ivol::kPredictedHeaderSize,
                                          payload.size() - ivol::kPredictedHeaderSize);
  if (got != planes.size()) throw std::runtime_error("entropy_study: a codec 3 frame did not decode");
  std::vector<unsigned> z(n);
  for (std::size_t i = 0; i < n; ++i) z[i] = planes[i] | unsigned{planes[n + i]} << 8;
  return z;
}

void model_brick(const std::vector<unsigned>& z, const ivol::BrickDims& d, Sizes& s) {
  std::vector<double> order0(65536, 0), tokens(kContexts * kTokens, 0), learnt(kContexts * kTokens, 0),
      seen(kContexts, 0);
  std::vector<std::vector<std::uint8_t>> parts(kContexts + 1);  // each context's tokens, then the bits below
  std::uint64_t pending = 0;
  int pending_bits = 0;
  double raw_bits = 0, adaptive_bits = 0;
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::size_t i = 0;
  for (std::uint32_t zz = 0; zz < d[2]; ++zz)
    for (std::uint32_t y = 0; y < d[1]; ++y)
      for (std::uint32_t x = 0; x < d[0]; ++x, ++i) {
        const unsigned r = z[i];
        const int b = bit_length(r);
        const int bl = x ? bit_length(z[i - 1]) : 0, bu = y ? bit_length(z[i - sy]) : 0,
                  bb = zz ? bit_length(z[i - sz]) : 0;
        const int ctx = std::min(kContexts - 1, (2 * bl + bu + bb + 1) / 3);
        const int t = token(r, b);
        order0[r] += 1;
        tokens[ctx * kTokens + t] += 1;
        raw_bits += b > 2 ? b - 2 : 0;
        parts[ctx].push_back(static_cast<std::uint8_t>(t));
        if (b > 2) {
          pending |= std::uint64_t{r & ((1u << (b - 2)) - 1)} << pending_bits;
          for (pending_bits += b - 2; pending_bits >= 8; pending_bits -= 8, pending >>= 8)
            parts[kContexts].push_back(static_cast<std::uint8_t>(pending));
        }
        double& count = learnt[ctx * kTokens + t];
        adaptive_bits -= std::log2((count + 0.5) / (seen[ctx] + 0.5 * kTokens));
        count += 1;
        seen[ctx] += 1;
      }
  if (pending_bits) parts[kContexts].push_back(static_cast<std::uint8_t>(pending));
  parts.erase(std::remove_if(parts.begin(), parts.end(), [](const auto& p) { return p.empty(); }), parts.end());
  s.split += static_cast<double>(ivol::kPredictedHeaderSize + 4 * kContexts + frame_of_parts(parts));
  s.order0 += entropy_bits(order0.data(), 65536) / 8;
  double h = raw_bits;
  for (int c = 0; c < kContexts; ++c) h += entropy_bits(tokens.data() + c * kTokens, kTokens);
  s.static_ctx += h / 8;
  s.adaptive += (adaptive_bits + raw_bits) / 8;
  s.static12 += static_table_bytes(z, d);
}

void run(const char* label, const std::vector<std::uint16_t>& volume, std::uint32_t n, unsigned log2,
         ivol::ValueEncoding encoding) {
  const std::uint32_t edge = 1u << log2;
  Sizes s;
  for (std::uint32_t z0 = 0; z0 < n; z0 += edge)
    for (std::uint32_t y0 = 0; y0 < n; y0 += edge)
      for (std::uint32_t x0 = 0; x0 < n; x0 += edge) {
        const ivol::BrickDims d{std::min(edge, n - x0), std::min(edge, n - y0), std::min(edge, n - z0)};
        std::vector<std::uint16_t> brick;
        for (std::uint32_t z = z0; z < z0 + d[2]; ++z)
          for (std::uint32_t y = y0; y < y0 + d[1]; ++y)
            for (std::uint32_t x = x0; x < x0 + d[0]; ++x) brick.push_back(volume[(std::size_t{z} * n + y) * n + x]);
        model_brick(residuals(brick, d, encoding, s), d, s);
      }
  auto vs = [&](double v) { return 100.0 * (v / s.codec3 - 1.0); };
  std::printf(
      "| %s | %.0f | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f "
      "(%+.1f %%; %+.2f %% of coder 2) |\n",
      label, s.codec3, s.order0, vs(s.order0), s.static_ctx, vs(s.static_ctx), s.adaptive, vs(s.adaptive), s.split,
      vs(s.split), s.coder2, vs(s.coder2), s.static12, vs(s.static12), 100.0 * (s.static12 / s.coder2 - 1.0));
}

}  // namespace

int main(int argc, char** argv) {
  bench::VolumeArgs args;
  if (!bench::read_volume_args(argc, argv, "entropy_study VOLUME.f32 N [BRICK_LOG2]", args)) return 2;
  const std::uint32_t n = args.n;
  const unsigned log2 = args.log2;
  const bench::SixteenBitVolume& volume = args.volume;
  std::printf(
      "| %s | codec 3, coder 1 | order-0 | contexts, static | adaptive | split | coder 2 | static 12 |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|\n",
      argv[1]);
  run("binary16", volume.binary16, n, log2, ivol::ValueEncoding::Binary16);
  run("uint16", volume.codes, n, log2, ivol::ValueEncoding::UInt16);
  return 0;
}
