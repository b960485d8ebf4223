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
// The first three are entropies, not a coder: a real one adds a few bytes a
// brick.
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
  double codec3 = 0, order0 = 0, static_ctx = 0, adaptive = 0, split = 0;
};

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
                                ivol::ValueEncoding encoding, double& payload_bytes) {
  const std::vector<std::uint8_t> payload = ivol::encode_predicted(brick.data(), d, encoding);
  payload_bytes += static_cast<double>(payload.size());
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
        model_brick(residuals(brick, d, encoding, s.codec3), d, s);
      }
  auto vs = [&](double v) { return 100.0 * (v / s.codec3 - 1.0); };
  std::printf("| %s | %.0f | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f (%+.1f %%) | %.0f (%+.1f %%) |\n", label,
              s.codec3, s.order0, vs(s.order0), s.static_ctx, vs(s.static_ctx), s.adaptive, vs(s.adaptive), s.split,
              vs(s.split));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: entropy_study VOLUME.f32 N [BRICK_LOG2]\n");
    return 2;
  }
  const auto n = static_cast<std::uint32_t>(std::stoul(argv[2]));
  const unsigned log2 = argc > 3 ? static_cast<unsigned>(std::stoul(argv[3])) : 5;
  bench::SixteenBitVolume volume;
  try {
    volume = bench::read_sixteen_bit(argv[1], n);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 2;
  }
  std::printf("| %s | codec 3 | order-0 | contexts, static | adaptive | split |\n|---|---:|---:|---:|---:|---:|\n",
              argv[1]);
  run("binary16", volume.binary16, n, log2, ivol::ValueEncoding::Binary16);
  run("uint16", volume.codes, n, log2, ivol::ValueEncoding::UInt16);
  return 0;
}
