// Codec 3, predicted 16-bit (spec §7.2). The encoder and the decoder share
// one walk over the brick's rows (walk_rows) and one row arithmetic
// (predicted_rows.hpp), so that they predict every voxel from exactly the
// same neighbours with exactly the same integer arithmetic.
#include "ivol/predicted_codec.hpp"

#include <zstd.h>
#include <zstd_errors.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#include "ivol/error.hpp"
#include "predicted_fit.hpp"
#include "predicted_rows.hpp"
#include "residual_lanes.hpp"
#include "residual_tokens.hpp"
#include "zstd_parts.hpp"

namespace ivol {
namespace {

using detail::PredictorTaps;
using detail::RowNeighbours;
using detail::RowPredictor;

constexpr std::uint8_t kPredictorLinear = 1;   // seven integer taps and a shift
constexpr std::uint8_t kMapIdentity = 0;       // the u16 as it is
constexpr std::uint8_t kMapBinary16Order = 1;  // binary16 bit patterns in numeric order
constexpr std::uint8_t kEntropyZstdPlanes = 1;
constexpr std::uint8_t kEntropyTokens = 2;  // rANS over tokens with contexts (§7.2.1)
constexpr std::uint8_t kEntropyLanes = 3;   // the same tokens under stored tables, 32 states (§7.2.2)
constexpr unsigned kMaxShift = 15;

// Negative numbers reversed below the positive ones: -0 (0x8000) becomes
// 0x7FFF, right below +0 (0x8000); a bijection on all 65536 patterns. Written
// without branches (the sign bit spread over the word) so that it vectorises.
std::uint16_t map_binary16(std::uint16_t v) {
  const auto sign = static_cast<std::uint16_t>(static_cast<std::int16_t>(v) >> 15);
  return static_cast<std::uint16_t>(v ^ (sign | 0x8000));
}

std::uint16_t unmap_binary16(std::uint16_t u) {
  const auto sign = static_cast<std::uint16_t>(static_cast<std::int16_t>(u) >> 15);
  return static_cast<std::uint16_t>(u ^ (static_cast<std::uint16_t>(~sign) | 0x8000));
}

std::int64_t clamp_u16(std::int64_t p) { return p < 0 ? 0 : p > 65535 ? 65535 : p; }

// Prediction for a voxel on the brick's low faces (spec §7.2): the Lorenzo
// predictor over the axes along which it has a neighbour.
std::uint16_t face_prediction(const std::uint16_t* u, std::size_t i, bool ax, bool ay, bool az, std::ptrdiff_t sy,
                              std::ptrdiff_t sz) {
  const int axes = int{ax} + int{ay} + int{az};
  if (axes == 0) return 0;
  const std::ptrdiff_t at = static_cast<std::ptrdiff_t>(i);
  if (axes == 1) return u[at - (ax ? 1 : ay ? sy : sz)];
  const std::ptrdiff_t s1 = ax ? 1 : sy;
  const std::ptrdiff_t s2 = az ? sz : sy;
  return static_cast<std::uint16_t>(clamp_u16(std::int64_t{u[at - s1]} + u[at - s2] - u[at - s1 - s2]));
}

// Visits the brick's rows in raster order: `face(i, x0, x1, y, z)` for the
// voxels x0 .. x1 of a row predicted by face_prediction (whole rows with y or
// z = 0, the first voxel of the others), `interior(c, neighbours)` for the
// rest of a row with y, z > 0 (c points at the row's first voxel).
template <class Face, class Interior>
void walk_rows(const BrickDims& d, std::uint16_t* u, Face&& face, Interior&& interior) {
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y, i += d[0]) {
      if (y == 0 || z == 0 || d[0] == 1) {
        face(i, y, z, d[0]);
        continue;
      }
      face(i, y, z, 1);
      std::uint16_t* c = u + i;
      interior(c, RowNeighbours{c - sy, c - sz, c - sy - sz});
    }
}

// Zigzag residuals of the voxels a face predicts, into z[].
void face_residuals(const BrickDims& d, const std::uint16_t* u, std::uint16_t* z) {
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  walk_rows(
      d, const_cast<std::uint16_t*>(u),
      [&](std::size_t i, std::uint32_t y, std::uint32_t zz, std::uint32_t count) {
        for (std::uint32_t x = 0; x < count; ++x)
          z[i + x] = detail::zigzag16(u[i + x], face_prediction(u, i + x, x > 0, y > 0, zz > 0, sy, sz));
      },
      [](std::uint16_t*, const RowNeighbours&) {});
}

// Σ of the bit lengths of z[0 .. len): floor(log2(2z + 1)), the exponent of
// 2z + 1 as a binary32 (exact below 2^24), so that the loop vectorises where
// a count of leading zeros per voxel does not (it took a quarter of the
// candidates' time).
std::uint32_t bit_lengths(const std::uint16_t* z, std::uint32_t len) {
  std::uint32_t sum = 0;
  for (std::uint32_t x = 0; x < len; ++x) {
    const float f = static_cast<float>(2 * static_cast<std::int32_t>(z[x]) + 1);
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    sum += (bits >> 23) - 127;
  }
  return sum;
}

// Zigzag residuals of the interior voxels of the sample's rows under
// `taps` into z[] (the other rows' are left as they are); returns the sum
// of their bit lengths (what the candidate taps are judged by: the faces'
// residuals do not depend on the taps).
// With `others`, the rows the sample leaves out instead (their cost is not
// summed): the winner's sampled rows are already in z[].
std::uint64_t interior_residuals(const BrickDims& d, const PredictorTaps& taps, const std::uint16_t* u,
                                 std::uint16_t* z, detail::RowSample sample = {}, bool others = false) {
  const RowPredictor p(taps);
  std::uint64_t cost = 0;
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  if (d[0] < 2) return 0;  // every voxel is on a face
  const std::uint32_t step = others ? 1 : sample.step;
  for (std::uint32_t layer = 1; layer < d[2]; layer += step)
    for (std::uint32_t y = 1; y < d[1]; y += step) {
      if (others && (layer - 1) % sample.step == 0 && (y - 1) % sample.step == 0) continue;
      const std::uint16_t* c = u + layer * sz + y * sy;
      const RowNeighbours n{c - sy, c - sz, c - sy - sz};
      std::uint16_t* row = z + (c - u);
      if (p.narrow)
        detail::residual_row<std::int32_t>(p, c, n, detail::first_x(u, n), d[0], row);
      else
        detail::residual_row<std::int64_t>(p, c, n, detail::first_x(u, n), d[0], row);
      if (!others) cost += bit_lengths(row + 1, d[0] - 1);
    }
  return cost;
}

void check_frame(const std::uint8_t* frame, std::size_t size, std::size_t content_size) {
  auto bad = [](const std::string& what) { throw Error(ErrorClass::Malformed, "codec 3: " + what); };
  static constexpr unsigned char kMagic[4] = {0x28, 0xB5, 0x2F, 0xFD};
  if (size < 4 || std::memcmp(frame, kMagic, 4) != 0) bad("the residuals are not a zstd frame");
  const unsigned long long content = ZSTD_getFrameContentSize(frame, size);
  if (content == ZSTD_CONTENTSIZE_UNKNOWN) bad("the zstd frame does not carry Frame_Content_Size");
  if (content == ZSTD_CONTENTSIZE_ERROR) bad("the zstd frame header is invalid");
  if (content != content_size)
    bad("the zstd frame holds " + std::to_string(content) + " bytes, the brick needs " + std::to_string(content_size));
  if (ZSTD_getDictID_fromFrame(frame, size) != 0) bad("the zstd frame needs a dictionary");
  const std::size_t frame_size = ZSTD_findFrameCompressedSize(frame, size);
  if (ZSTD_isError(frame_size) || frame_size != size)
    bad("the bytes after the codec header are not exactly one complete zstd frame");
}

// Entropy coder 1: the residuals from their byte planes in one zstd frame.
void decode_zstd_planes(const std::uint8_t* frame, std::size_t frame_size, std::size_t n, std::uint16_t* residuals) {
  auto bad = [](ErrorClass c, const std::string& what) { throw Error(c, "codec 3: " + what); };
  thread_local std::vector<std::uint8_t> planes;  // every byte written before it is read
  planes.resize(2 * n);
  check_frame(frame, frame_size, planes.size());
  ZSTD_DCtx* const context = detail::thread_decompression_context();
  const std::size_t got = ZSTD_decompressDCtx(context, planes.data(), planes.size(), frame, frame_size);
  if (ZSTD_isError(got)) {
    if (ZSTD_getErrorCode(got) == ZSTD_error_checksum_wrong)
      bad(ErrorClass::Checksum, "the zstd content checksum does not match");
    bad(ErrorClass::Malformed, std::string("zstd cannot decode the residuals: ") + ZSTD_getErrorName(got));
  }
  if (got != planes.size())
    bad(ErrorClass::Malformed,
        "the residuals decoded to " + std::to_string(got) + " bytes, the brick needs " + std::to_string(planes.size()));
  const std::uint8_t *lo = planes.data(), *hi = planes.data() + n;
  for (std::size_t i = 0; i < n; ++i) residuals[i] = static_cast<std::uint16_t>(lo[i] | hi[i] << 8);
}

}  // namespace

std::uint64_t predicted_payload_bound(std::uint64_t voxels) {
  return kPredictedHeaderSize + ZSTD_compressBound(static_cast<std::size_t>(2 * voxels));
}

std::vector<std::uint8_t> encode_predicted(const std::uint16_t* values, const BrickDims& dims, ValueEncoding encoding,
                                           const PredictedOptions& options) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (n == 0) throw Error(ErrorClass::InvalidArgument, "encode_predicted: an empty brick");
  const std::uint8_t map = encoding == ValueEncoding::Binary16 ? kMapBinary16Order : kMapIdentity;
  std::vector<std::uint16_t> u(values, values + n);
  if (map == kMapBinary16Order)
    for (std::size_t i = 0; i < n; ++i) u[i] = map_binary16(u[i]);

  // Candidates judged by the sum of their residuals' bit lengths (about what
  // either coder spends on them; bench/RESULTS.md: 0-0.3 % smaller files
  // than the sum of magnitudes, which outliers sway). The fits and the
  // judging see the rows of detail::row_sample (a quarter of a large brick's):
  // the winner's residuals are then made for every row; with every row
  // sampled, the best candidate's are kept instead (no second pass).
  const detail::RowSample sample = detail::row_sample(dims);
  std::vector<std::uint16_t> best_z(n), candidate_z(n);
  PredictorTaps taps = detail::kLorenzoTaps;
  std::uint64_t best = ~std::uint64_t{0};
  bool have = false;
  auto consider = [&](const PredictorTaps& candidate) {
    const std::uint64_t cost = interior_residuals(dims, candidate, u.data(), candidate_z.data(), sample);
    if (!have || cost < best) best = cost, taps = candidate, have = true, best_z.swap(candidate_z);
  };
  if (options.taps != PredictedOptions::Taps::LeastSquares) consider(detail::kLorenzoTaps);
  if (options.taps != PredictedOptions::Taps::Lorenzo) {
    detail::BrickMoments moments;
    PredictorTaps fitted;
    if (detail::brick_moments(dims, u.data(), moments, sample)) {
      if (detail::fit_least_squares(moments, fitted)) consider(fitted);
      if (detail::fit_least_squares_with_level(dims, u.data(), moments, fitted, sample)) consider(fitted);
    }
  }
  if (!have)
    interior_residuals(dims, taps, u.data(), best_z.data());
  else if (!sample.all())
    interior_residuals(dims, taps, u.data(), best_z.data(), sample, true);
  face_residuals(dims, u.data(), best_z.data());

  std::vector<std::uint8_t> out(kPredictedHeaderSize);
  out.reserve(predicted_payload_bound(n));
  out[0] = kPredictorLinear;
  out[1] = map;
  out[2] = static_cast<std::uint8_t>(taps.shift);
  out[3] = kEntropyZstdPlanes;
  for (int k = 0; k < 7; ++k) {
    const auto tap = static_cast<std::uint16_t>(static_cast<std::int16_t>(taps.t[k]));
    out[4 + 2 * k] = static_cast<std::uint8_t>(tap);
    out[5 + 2 * k] = static_cast<std::uint8_t>(tap >> 8);
  }
  for (int k = 0; k < 4; ++k) out[18 + k] = static_cast<std::uint8_t>(static_cast<std::uint32_t>(taps.bias) >> (8 * k));
  out[22] = out[23] = 0;  // reserved

  auto zstd_planes = [&] {
    std::vector<std::uint8_t> planes(2 * n);
    for (std::size_t i = 0; i < n; ++i) {
      planes[i] = static_cast<std::uint8_t>(best_z[i]);
      planes[n + i] = static_cast<std::uint8_t>(best_z[i] >> 8);
    }
    thread_local std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
    if (!context) throw Error(ErrorClass::Io, "zstd: cannot create a compression context");
    ZSTD_CCtx_reset(context.get(), ZSTD_reset_session_and_parameters);
    ZSTD_CCtx_setParameter(context.get(), ZSTD_c_compressionLevel, options.zstd_level);
    ZSTD_CCtx_setParameter(context.get(), ZSTD_c_contentSizeFlag, 1);
    // Each plane ends a zstd block: entropy tables of its own (zstd_parts.hpp).
    detail::compress_parts(context.get(), {{planes.data(), n}, {planes.data() + n, n}}, out, kPredictedHeaderSize);
  };
  // Either coder's payload obeys codec 3's one limit on stored bytes (spec §7).
  const std::size_t limit = ZSTD_compressBound(2 * n);
  if (options.entropy == PredictedOptions::Entropy::ZstdPlanes) {
    zstd_planes();
    return out;
  }
  std::vector<std::uint8_t> tokens(out.begin(), out.begin() + kPredictedHeaderSize);
  // Coder 3 in bricks of 2^18 voxels (64³) or more unless coder 2 was asked
  // for: there its stored tables and states weigh nothing (−0.05 to +0.04 %
  // of coder 2's bytes on the 256³ phantoms) and it decodes twice as fast;
  // in 32³ bricks they cost 0.3–0.5 % (bench/RESULTS.md, "Entropy coder 3"),
  // which Auto pays at the default levels for coder 3's speed.
  constexpr std::size_t kLanesFromVoxels = std::size_t{1} << 18;
  const bool lanes = options.entropy == PredictedOptions::Entropy::Lanes ||
                     (options.entropy == PredictedOptions::Entropy::Auto && options.zstd_level <= 3) ||
                     (options.entropy != PredictedOptions::Entropy::Tokens && n >= kLanesFromVoxels);
  tokens[3] = lanes ? kEntropyLanes : kEntropyTokens;
  const bool coded = lanes ? detail::encode_residual_lanes(best_z.data(), dims, limit, tokens)
                           : detail::encode_residual_tokens(best_z.data(), dims, limit, tokens);
  if (coded && options.entropy == PredictedOptions::Entropy::Tokens) return tokens;
  // Coder 1 wins only where coder 2 spends under about a bit a voxel (air
  // and flat material, where zstd's matches beat any per-voxel cost), and
  // there zstd is fast: elsewhere trying it cost a fifth of the encoding
  // time and saved at most 23 bytes of 13 MB (bench/RESULTS.md, issue 22).
  // Small bricks (a volume's edges) try both: coder 2's 12 bytes of states
  // and length weigh there, and zstd costs nothing to try.
  constexpr std::size_t kTryZstdBelowBitsPerVoxel = 1;
  constexpr std::size_t kTryZstdBelowVoxels = 4096;
  if (coded && n >= kTryZstdBelowVoxels && 8 * (tokens.size() - kPredictedHeaderSize) >= kTryZstdBelowBitsPerVoxel * n)
    return tokens;
  zstd_planes();
  if (coded && tokens.size() <= out.size()) return tokens;
  return out;
}

namespace {

// Decodes the brick's values from their residuals z[]. An interior row's
// voxels wait on one another (decode_row), so its rows are decoded two at a
// time where they can be, their chains interleaved: row (y, z) with row
// (y − 1, z + 1), whose neighbours (rows (y − 2, z + 1), (y − 1, z) and
// (y − 2, z)) are decoded before, and which is not one of row (y, z)'s. So
// layers z and z + 1 are walked together, the second a row behind. Every
// voxel is predicted from the same neighbours as in raster order: the
// values are the same.
template <class Acc>
void decode_rows(const RowPredictor& p, const BrickDims& d, const std::uint16_t* z, std::uint16_t* out) {
  const std::uint32_t nx = d[0], ny = d[1], nz = d[2];
  const std::ptrdiff_t sy = nx, sz = std::ptrdiff_t{nx} * ny;
  std::vector<Acc> partial(2 * std::size_t{nx});
  std::vector<std::uint16_t> delta(2 * std::size_t{nx});
  auto at = [&](std::uint32_t y, std::uint32_t zz) { return (std::size_t{zz} * ny + y) * nx; };
  // The voxels x < count of a row that the faces' predictor takes.
  auto face = [&](std::uint32_t y, std::uint32_t zz, std::uint32_t count) {
    const std::size_t i = at(y, zz);
    for (std::uint32_t x = 0; x < count; ++x)
      out[i + x] = detail::unzigzag16(z[i + x], face_prediction(out, i + x, x > 0, y > 0, zz > 0, sy, sz));
  };
  auto interior = [&](std::uint32_t y, std::uint32_t zz) { return y > 0 && zz > 0 && nx > 1; };
  auto neighbours = [&](std::uint16_t* c) { return RowNeighbours{c - sy, c - sz, c - sy - sz}; };
  auto row = [&](std::uint32_t y, std::uint32_t zz) {
    if (!interior(y, zz)) return face(y, zz, nx);
    face(y, zz, 1);
    std::uint16_t* c = out + at(y, zz);
    const RowNeighbours n = neighbours(c);
    detail::decode_row<Acc>(p, c, n, detail::first_x(out, n), nx, z + at(y, zz), partial.data(), delta.data());
  };
  for (std::uint32_t y = 0; y < ny; ++y) row(y, 0);
  for (std::uint32_t zz = 1; zz < nz; zz += 2) {
    if (zz + 1 == nz) {
      for (std::uint32_t y = 0; y < ny; ++y) row(y, zz);
      break;
    }
    for (std::uint32_t y = 0; y <= ny; ++y) {
      if (y < ny && y >= 1 && interior(y, zz) && interior(y - 1, zz + 1)) {
        face(y, zz, 1);
        face(y - 1, zz + 1, 1);
        std::uint16_t* c = out + at(y, zz);
        std::uint16_t* c2 = out + at(y - 1, zz + 1);
        const RowNeighbours n = neighbours(c), n2 = neighbours(c2);
        detail::decode_row_pair<Acc>(p, c, n, detail::first_x(out, n), z + at(y, zz), c2, n2, detail::first_x(out, n2),
                                     z + at(y - 1, zz + 1), nx, partial.data(), delta.data());
        continue;
      }
      if (y < ny) row(y, zz);
      if (y >= 1) row(y - 1, zz + 1);
    }
  }
}

}  // namespace

void decode_predicted(const std::uint8_t* payload, std::size_t size, const BrickDims& dims, std::uint16_t* out) {
  auto bad = [](ErrorClass c, const std::string& what) { throw Error(c, "codec 3: " + what); };
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (size < kPredictedHeaderSize)
    bad(ErrorClass::Malformed, "the payload of " + std::to_string(size) + " bytes is shorter than the codec header");
  if (payload[0] != kPredictorLinear)
    bad(ErrorClass::UnsupportedFeature, "predictor " + std::to_string(payload[0]) + " is not known");
  if (payload[1] != kMapIdentity && payload[1] != kMapBinary16Order)
    bad(ErrorClass::Malformed, "value map " + std::to_string(payload[1]) + " is not 0 or 1");
  if (payload[2] > kMaxShift) bad(ErrorClass::Malformed, "shift " + std::to_string(payload[2]) + " exceeds 15");
  if (payload[3] != kEntropyZstdPlanes && payload[3] != kEntropyTokens && payload[3] != kEntropyLanes)
    bad(ErrorClass::UnsupportedFeature, "entropy coder " + std::to_string(payload[3]) + " is not known");
  if (payload[22] != 0 || payload[23] != 0) bad(ErrorClass::Malformed, "the reserved bytes 22 .. 24 are not 0");
  PredictorTaps taps;
  taps.shift = payload[2];
  for (int k = 0; k < 7; ++k)
    taps.t[k] = static_cast<std::int16_t>(static_cast<std::uint16_t>(payload[4 + 2 * k] | payload[5 + 2 * k] << 8));
  taps.bias = static_cast<std::int32_t>(std::uint32_t{payload[18]} | std::uint32_t{payload[19]} << 8 |
                                        std::uint32_t{payload[20]} << 16 | std::uint32_t{payload[21]} << 24);

  // Kept per thread: either coder writes every residual, and a brick's
  // 64 KiB zeroed anew for every brick showed in the profile of a whole read.
  thread_local std::vector<std::uint16_t> residuals;
  residuals.resize(n);
  if (payload[3] == kEntropyTokens)
    detail::decode_residual_tokens(payload + kPredictedHeaderSize, size - kPredictedHeaderSize, dims, residuals.data());
  else if (payload[3] == kEntropyLanes)
    detail::decode_residual_lanes(payload + kPredictedHeaderSize, size - kPredictedHeaderSize, dims, residuals.data());
  else
    decode_zstd_planes(payload + kPredictedHeaderSize, size - kPredictedHeaderSize, n, residuals.data());
  const RowPredictor p(taps);
  if (p.decode_narrow)
    decode_rows<std::int32_t>(p, dims, residuals.data(), out);
  else
    decode_rows<std::int64_t>(p, dims, residuals.data(), out);
  if (payload[1] == kMapBinary16Order)
    for (std::size_t i = 0; i < n; ++i) out[i] = unmap_binary16(out[i]);
}

}  // namespace ivol
