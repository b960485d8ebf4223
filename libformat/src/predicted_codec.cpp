// Codec 3, predicted 16-bit (spec §7.2). The encoder and the decoder share
// one walk over the brick (walk_brick), so that they predict every voxel
// from exactly the same neighbours with exactly the same integer arithmetic.
#include "ivol/predicted_codec.hpp"

#include <zstd.h>
#include <zstd_errors.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#include "ivol/error.hpp"

namespace ivol {
namespace {

constexpr std::uint8_t kPredictorLinear = 1;   // seven integer taps and a shift
constexpr std::uint8_t kMapIdentity = 0;       // the u16 as it is
constexpr std::uint8_t kMapBinary16Order = 1;  // binary16 bit patterns in numeric order
constexpr std::uint8_t kEntropyZstdPlanes = 1;
constexpr unsigned kMaxShift = 15;
// Least-squares taps are stored in units of 2^-12: fine enough that rounding
// them costs nothing measurable, coarse enough for taps up to ±8 in an i16.
constexpr unsigned kLeastSquaresShift = 12;

struct Taps {
  unsigned shift = 0;
  // Neighbours (x-1), (y-1), (z-1), (x-1,y-1), (x-1,z-1), (y-1,z-1), (x-1,y-1,z-1).
  std::array<std::int32_t, 7> t{};
  std::int32_t bias = 0;  // added after the shift: a level that noise-dominated bricks predict best
};
constexpr Taps kLorenzo{0, {1, 1, 1, -1, -1, -1, 1}, 0};

std::uint16_t map_value(std::uint16_t v, std::uint8_t map) {
  if (map == kMapIdentity) return v;
  // Negative numbers reversed below the positive ones: -0 (0x8000) becomes
  // 0x7FFF, right below +0 (0x8000); a bijection on all 65536 patterns.
  return (v & 0x8000) ? static_cast<std::uint16_t>(v ^ 0xFFFF) : static_cast<std::uint16_t>(v | 0x8000);
}

std::uint16_t unmap_value(std::uint16_t u, std::uint8_t map) {
  if (map == kMapIdentity) return u;
  return (u & 0x8000) ? static_cast<std::uint16_t>(u ^ 0x8000) : static_cast<std::uint16_t>(u ^ 0xFFFF);
}

std::int64_t clamp_u16(std::int64_t p) { return p < 0 ? 0 : p > 65535 ? 65535 : p; }

// Prediction for a voxel on the brick's low faces (spec §7.2): the Lorenzo
// predictor over the axes along which it has a neighbour.
std::int64_t face_prediction(const std::uint16_t* u, std::size_t i, bool ax, bool ay, bool az, std::size_t sy,
                             std::size_t sz) {
  const int axes = int{ax} + int{ay} + int{az};
  if (axes == 0) return 0;
  if (axes == 1) return u[i - (ax ? 1 : ay ? sy : sz)];
  const std::size_t s1 = ax ? 1 : sy;
  const std::size_t s2 = az ? sz : sy;
  return clamp_u16(std::int64_t{u[i - s1]} + u[i - s2] - u[i - s1 - s2]);
}

// Visits every voxel in raster order with its prediction; `at(i, p)` must
// leave u[i] final before it returns (the decoder writes it there).
template <class F>
void walk_brick(const BrickDims& d, const Taps& taps, std::uint16_t* u, F&& at) {
  // Signed strides: c[-sy] steps back, which unsigned arithmetic would wrap.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  const std::int64_t round = taps.shift ? std::int64_t{1} << (taps.shift - 1) : 0;
  const auto& t = taps.t;
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y) {
      if (y == 0 || z == 0) {
        for (std::uint32_t x = 0; x < d[0]; ++x, ++i)
          at(i, static_cast<std::uint16_t>(face_prediction(u, i, x > 0, y > 0, z > 0, sy, sz)));
        continue;
      }
      at(i, static_cast<std::uint16_t>(face_prediction(u, i, false, true, true, sy, sz)));
      ++i;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++i) {
        const std::uint16_t* c = u + i;
        const std::int64_t sum = t[0] * std::int64_t{c[-1]} + t[1] * std::int64_t{c[-sy]} +
                                 t[2] * std::int64_t{c[-sz]} + t[3] * std::int64_t{c[-1 - sy]} +
                                 t[4] * std::int64_t{c[-1 - sz]} + t[5] * std::int64_t{c[-sy - sz]} +
                                 t[6] * std::int64_t{c[-1 - sy - sz]};
        at(i, static_cast<std::uint16_t>(clamp_u16(((sum + round) >> taps.shift) + taps.bias)));
      }
    }
}

std::uint16_t zigzag(std::uint16_t value, std::uint16_t prediction) {
  const auto s = static_cast<std::int16_t>(static_cast<std::uint16_t>(value - prediction));
  return s >= 0 ? static_cast<std::uint16_t>(2 * s) : static_cast<std::uint16_t>(-2 * std::int32_t{s} - 1);
}

std::uint16_t unzigzag(std::uint16_t z, std::uint16_t prediction) {
  const std::int32_t s = (z & 1) ? -(std::int32_t{z} + 1) / 2 : std::int32_t{z} / 2;
  return static_cast<std::uint16_t>(prediction + s);
}

// Solves the k x k system a x = b (row-major a) by elimination with partial
// pivoting; false when it is singular.
bool solve(double* a, double* b, int k) {
  for (int c = 0; c < k; ++c) {
    int pivot = c;
    for (int r = c + 1; r < k; ++r)
      if (std::fabs(a[r * k + c]) > std::fabs(a[pivot * k + c])) pivot = r;
    if (!(std::fabs(a[pivot * k + c]) > 1e-9)) return false;
    if (pivot != c) {
      for (int j = 0; j < k; ++j) std::swap(a[c * k + j], a[pivot * k + j]);
      std::swap(b[c], b[pivot]);
    }
    for (int r = c + 1; r < k; ++r) {
      const double f = a[r * k + c] / a[c * k + c];
      for (int j = c; j < k; ++j) a[r * k + j] -= f * a[c * k + j];
      b[r] -= f * b[c];
    }
  }
  for (int c = k - 1; c >= 0; --c) {
    double s = b[c];
    for (int j = c + 1; j < k; ++j) s -= a[c * k + j] * b[j];
    b[c] = s / a[c * k + c];
  }
  return true;
}

// Least-squares taps for the brick's interior voxels, constrained to sum to
// one (so that rounding them to integers costs nothing on a constant level):
// the value minus its x neighbour is fitted on the other six neighbours minus
// the x neighbour. False when too few voxels or the fit is degenerate.
bool fit_least_squares(const BrickDims& d, const std::uint16_t* u, Taps& out) {
  if (d[0] < 2 || d[1] < 2 || d[2] < 2 || (d[0] - 1) * std::uint64_t{d[1] - 1} * (d[2] - 1) < 64) return false;
  // Signed strides: c[-sy] steps back, which unsigned arithmetic would wrap.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  double ata[36] = {}, atb[6] = {};
  for (std::uint32_t z = 1; z < d[2]; ++z)
    for (std::uint32_t y = 1; y < d[1]; ++y) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        const double a = c[-1];
        const double n[6] = {c[-sy] - a,     c[-sz] - a,      c[-1 - sy] - a,
                             c[-1 - sz] - a, c[-sy - sz] - a, c[-1 - sy - sz] - a};
        const double v = c[0] - a;
        for (int r = 0; r < 6; ++r) {
          atb[r] += n[r] * v;
          for (int k = r; k < 6; ++k) ata[r * 6 + k] += n[r] * n[k];
        }
      }
    }
  for (int r = 0; r < 6; ++r)
    for (int k = 0; k < r; ++k) ata[r * 6 + k] = ata[k * 6 + r];
  if (!solve(ata, atb, 6)) return false;
  out.shift = kLeastSquaresShift;
  std::int32_t rest = 0;
  for (int r = 0; r < 6; ++r) {
    const double scaled = std::nearbyint(atb[r] * (1 << kLeastSquaresShift));
    if (!(std::fabs(scaled) <= 16384)) return false;
    out.t[r + 1] = static_cast<std::int32_t>(scaled);
    rest += out.t[r + 1];
  }
  out.t[0] = (1 << kLeastSquaresShift) - rest;  // the taps sum to exactly 2^shift
  return out.t[0] >= -32768 && out.t[0] <= 32767;
}

// Least-squares taps with a level (intercept), for bricks where noise
// dominates: predicting every voxel from its neighbours' sum would add their
// noise, predicting the level does not. Fitted on values less the brick's
// first interior voxel (so that the sums keep their precision); the level is
// computed after the taps are rounded, so their rounding costs nothing.
bool fit_least_squares_with_level(const BrickDims& d, const std::uint16_t* u, Taps& out) {
  if (d[0] < 2 || d[1] < 2 || d[2] < 2 || (d[0] - 1) * std::uint64_t{d[1] - 1} * (d[2] - 1) < 64) return false;
  // Signed strides: c[-sy] steps back, which unsigned arithmetic would wrap.
  const std::ptrdiff_t sy = d[0], sz = std::ptrdiff_t{d[0]} * d[1];
  const double ref = u[sz + sy + 1];
  double sum_n[7] = {}, sum_v = 0, nn[49] = {}, nv[7] = {}, count = 0;
  auto neighbours = [&](const std::uint16_t* c, double* n) {
    n[0] = c[-1] - ref, n[1] = c[-sy] - ref, n[2] = c[-sz] - ref, n[3] = c[-1 - sy] - ref;
    n[4] = c[-1 - sz] - ref, n[5] = c[-sy - sz] - ref, n[6] = c[-1 - sy - sz] - ref;
  };
  for (std::uint32_t z = 1; z < d[2]; ++z)
    for (std::uint32_t y = 1; y < d[1]; ++y) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        double n[7];
        neighbours(c, n);
        const double v = c[0] - ref;
        count += 1, sum_v += v;
        for (int r = 0; r < 7; ++r) {
          sum_n[r] += n[r], nv[r] += n[r] * v;
          for (int k = r; k < 7; ++k) nn[r * 7 + k] += n[r] * n[k];
        }
      }
    }
  double cov[49], rhs[7];
  for (int r = 0; r < 7; ++r) {
    rhs[r] = nv[r] - sum_n[r] * sum_v / count;
    for (int k = r; k < 7; ++k) cov[r * 7 + k] = cov[k * 7 + r] = nn[r * 7 + k] - sum_n[r] * sum_n[k] / count;
  }
  if (!solve(cov, rhs, 7)) return false;
  out.shift = kLeastSquaresShift;
  for (int r = 0; r < 7; ++r) {
    const double scaled = std::nearbyint(rhs[r] * (1 << kLeastSquaresShift));
    if (!(std::fabs(scaled) <= 32767)) return false;
    out.t[r] = static_cast<std::int32_t>(scaled);
  }
  // The level: the mean of what the rounded taps leave, over the interior.
  out.bias = 0;
  double left = 0;
  const std::int64_t round = std::int64_t{1} << (kLeastSquaresShift - 1);
  for (std::uint32_t z = 1; z < d[2]; ++z)
    for (std::uint32_t y = 1; y < d[1]; ++y) {
      const std::uint16_t* c = u + z * sz + y * sy + 1;
      for (std::uint32_t x = 1; x < d[0]; ++x, ++c) {
        const std::int64_t sum = out.t[0] * std::int64_t{c[-1]} + out.t[1] * std::int64_t{c[-sy]} +
                                 out.t[2] * std::int64_t{c[-sz]} + out.t[3] * std::int64_t{c[-1 - sy]} +
                                 out.t[4] * std::int64_t{c[-1 - sz]} + out.t[5] * std::int64_t{c[-sy - sz]} +
                                 out.t[6] * std::int64_t{c[-1 - sy - sz]};
        left += static_cast<double>(c[0] - ((sum + round) >> kLeastSquaresShift));
      }
    }
  out.bias = static_cast<std::int32_t>(std::nearbyint(left / count));
  return true;
}

// Sum of the residuals' magnitudes: what the candidate taps are judged by.
std::uint64_t residual_cost(const BrickDims& d, const Taps& taps, const std::uint16_t* u) {
  std::uint64_t cost = 0;
  walk_brick(d, taps, const_cast<std::uint16_t*>(u), [&](std::size_t i, std::uint16_t p) { cost += zigzag(u[i], p); });
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

}  // namespace

std::uint64_t predicted_payload_bound(std::uint64_t voxels) {
  return kPredictedHeaderSize + ZSTD_compressBound(static_cast<std::size_t>(2 * voxels));
}

std::vector<std::uint8_t> encode_predicted(const std::uint16_t* values, const BrickDims& dims, ValueEncoding encoding,
                                           const PredictedOptions& options) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (n == 0) throw Error(ErrorClass::InvalidArgument, "encode_predicted: an empty brick");
  const std::uint8_t map = encoding == ValueEncoding::Binary16 ? kMapBinary16Order : kMapIdentity;
  std::vector<std::uint16_t> u(n);
  for (std::size_t i = 0; i < n; ++i) u[i] = map_value(values[i], map);

  // Candidates judged by the sum of their residuals' magnitudes.
  Taps taps = kLorenzo;
  if (options.taps != PredictedOptions::Taps::Lorenzo) {
    std::uint64_t best =
        options.taps == PredictedOptions::Taps::Best ? residual_cost(dims, kLorenzo, u.data()) : ~std::uint64_t{0};
    Taps fitted;
    if (fit_least_squares(dims, u.data(), fitted))
      if (const std::uint64_t cost = residual_cost(dims, fitted, u.data()); cost < best) best = cost, taps = fitted;
    if (fit_least_squares_with_level(dims, u.data(), fitted))
      if (const std::uint64_t cost = residual_cost(dims, fitted, u.data()); cost < best) best = cost, taps = fitted;
  }

  std::vector<std::uint8_t> planes(2 * n);
  walk_brick(dims, taps, u.data(), [&](std::size_t i, std::uint16_t p) {
    const std::uint16_t z = zigzag(u[i], p);
    planes[i] = static_cast<std::uint8_t>(z);
    planes[n + i] = static_cast<std::uint8_t>(z >> 8);
  });

  std::vector<std::uint8_t> out(predicted_payload_bound(n));
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
  thread_local std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!context) throw Error(ErrorClass::Io, "zstd: cannot create a compression context");
  ZSTD_CCtx_reset(context.get(), ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_compressionLevel, options.zstd_level);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_contentSizeFlag, 1);
  const std::size_t size = ZSTD_compress2(context.get(), out.data() + kPredictedHeaderSize,
                                          out.size() - kPredictedHeaderSize, planes.data(), planes.size());
  if (ZSTD_isError(size))
    throw Error(ErrorClass::Io, std::string("zstd compression failed: ") + ZSTD_getErrorName(size));
  out.resize(kPredictedHeaderSize + size);
  return out;
}

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
  if (payload[3] != kEntropyZstdPlanes)
    bad(ErrorClass::UnsupportedFeature, "entropy coder " + std::to_string(payload[3]) + " is not known");
  if (payload[22] != 0 || payload[23] != 0) bad(ErrorClass::Malformed, "the reserved bytes 22 .. 24 are not 0");
  Taps taps;
  taps.shift = payload[2];
  for (int k = 0; k < 7; ++k)
    taps.t[k] = static_cast<std::int16_t>(static_cast<std::uint16_t>(payload[4 + 2 * k] | payload[5 + 2 * k] << 8));
  taps.bias = static_cast<std::int32_t>(std::uint32_t{payload[18]} | std::uint32_t{payload[19]} << 8 |
                                        std::uint32_t{payload[20]} << 16 | std::uint32_t{payload[21]} << 24);

  const std::uint8_t* frame = payload + kPredictedHeaderSize;
  const std::size_t frame_size = size - kPredictedHeaderSize;
  check_frame(frame, frame_size, 2 * n);
  thread_local std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> context(ZSTD_createDCtx(), ZSTD_freeDCtx);
  std::vector<std::uint8_t> planes(2 * n);
  const std::size_t got = ZSTD_decompressDCtx(context.get(), planes.data(), planes.size(), frame, frame_size);
  if (ZSTD_isError(got)) {
    if (ZSTD_getErrorCode(got) == ZSTD_error_checksum_wrong)
      bad(ErrorClass::Checksum, "the zstd content checksum does not match");
    bad(ErrorClass::Malformed, std::string("zstd cannot decode the residuals: ") + ZSTD_getErrorName(got));
  }
  if (got != planes.size())
    bad(ErrorClass::Malformed,
        "the residuals decoded to " + std::to_string(got) + " bytes, the brick needs " + std::to_string(planes.size()));
  walk_brick(dims, taps, out, [&](std::size_t i, std::uint16_t p) {
    out[i] = unzigzag(static_cast<std::uint16_t>(planes[i] | planes[n + i] << 8), p);
  });
  const std::uint8_t map = payload[1];
  if (map != kMapIdentity)
    for (std::size_t i = 0; i < n; ++i) out[i] = unmap_value(out[i], map);
}

}  // namespace ivol
