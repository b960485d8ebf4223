#include "fdk_native_filter.hpp"

#include <immintrin.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "native_threads.hpp"
#include "recon_layout.h"

// Compiled with -ffp-contract=off (recon/CMakeLists.txt): the fused
// multiply-adds below are those clang makes of fdk_filter_rows, written out.

namespace ivol::recon::detail {
namespace {

constexpr int kLanes = 16;

// One complex vector per point: the real parts of sixteen pairs' points and
// their imaginary parts, [point][lane].
struct Spectra {
  std::vector<float> re, im;
  explicit Spectra(int n) : re(static_cast<std::size_t>(n) * kLanes), im(static_cast<std::size_t>(n) * kLanes) {}
};

// fdk_filter_rows' stockham(): src → dst and back each stage; returns the
// buffer holding the result.
__attribute__((target("avx512f,fma"))) Spectra* stockham(Spectra* src, Spectra* dst, const float* twiddles, int log2n,
                                                         float direction) {
  const int half_n = 1 << (log2n - 1);
  for (int stage = 0; stage < log2n; ++stage) {
    const int span = 1 << stage;
    for (int j = 0; j < half_n; ++j) {
      const int k = j & (span - 1);
      const std::size_t at = static_cast<std::size_t>(j) * kLanes;
      const std::size_t at_b = static_cast<std::size_t>(j + half_n) * kLanes;
      const __m512 ax = _mm512_loadu_ps(&src->re[at]);
      const __m512 ay = _mm512_loadu_ps(&src->im[at]);
      const __m512 bx = _mm512_loadu_ps(&src->re[at_b]);
      const __m512 by = _mm512_loadu_ps(&src->im[at_b]);
      const int w = k << (log2n - 1 - stage);
      const __m512 wx = _mm512_set1_ps(twiddles[2 * w]);
      const __m512 wy = _mm512_set1_ps(twiddles[2 * w + 1] * direction);
      // t = (b.x·w.x − b.y·w.y, b.x·w.y + b.y·w.x): clang fuses each left
      // product with the right one rounded.
      const __m512 tx = _mm512_fmsub_ps(bx, wx, _mm512_mul_ps(by, wy));
      const __m512 ty = _mm512_fmadd_ps(bx, wy, _mm512_mul_ps(by, wx));
      const std::size_t out = static_cast<std::size_t>(((j - k) << 1) + k) * kLanes;
      const std::size_t out_b = out + static_cast<std::size_t>(span) * kLanes;
      _mm512_storeu_ps(&dst->re[out], _mm512_add_ps(ax, tx));
      _mm512_storeu_ps(&dst->im[out], _mm512_add_ps(ay, ty));
      _mm512_storeu_ps(&dst->re[out_b], _mm512_sub_ps(ax, tx));
      _mm512_storeu_ps(&dst->im[out_b], _mm512_sub_ps(ay, ty));
    }
    std::swap(src, dst);
  }
  return src;
}

// Row pairs [first, last) of the batch (pair p of view v is number
// v · pairs + p), sixteen at a time.
__attribute__((target("avx512f,fma"))) void filter_pairs(const NativeFilterBatch& b, std::size_t first,
                                                         std::size_t last) {
  const int n = 1 << b.log2n;
  const std::size_t pairs = static_cast<std::size_t>(b.band_rows + 1) / 2;
  Spectra one(n), two(n);
  for (std::size_t group = first; group < last; group += kLanes) {
    const int lanes = static_cast<int>(std::min<std::size_t>(kLanes, last - group));
    // The pairs' weighted rows, zero past the columns and for a band's odd
    // last row (the kernel's buffer_a).
    std::fill(one.re.begin(), one.re.end(), 0.0F);
    std::fill(one.im.begin(), one.im.end(), 0.0F);
    for (int l = 0; l < lanes; ++l) {
      const std::size_t view = (group + l) / pairs;
      const int row_a = static_cast<int>((group + l) % pairs) * 2;
      const float* image = b.weighted + view * static_cast<std::size_t>(b.band_rows) * b.columns;
      for (int i = 0; i < b.columns; ++i)
        one.re[static_cast<std::size_t>(i) * kLanes + l] = image[row_a * b.columns + i];
      if (row_a + 1 < b.band_rows)
        for (int i = 0; i < b.columns; ++i)
          one.im[static_cast<std::size_t>(i) * kLanes + l] = image[(row_a + 1) * b.columns + i];
    }
    Spectra* spectrum = stockham(&one, &two, b.twiddles, b.log2n, 1.0F);
    for (int i = 0; i < n; ++i) {
      const __m512 r = _mm512_set1_ps(b.response[i]);
      const std::size_t at = static_cast<std::size_t>(i) * kLanes;
      _mm512_storeu_ps(&spectrum->re[at], _mm512_mul_ps(_mm512_loadu_ps(&spectrum->re[at]), r));
      _mm512_storeu_ps(&spectrum->im[at], _mm512_mul_ps(_mm512_loadu_ps(&spectrum->im[at]), r));
    }
    Spectra* result = stockham(spectrum, spectrum == &one ? &two : &one, b.twiddles, b.log2n, -1.0F);
    for (int l = 0; l < lanes; ++l) {
      const std::size_t view = (group + l) / pairs;
      const int row_a = static_cast<int>((group + l) % pairs) * 2;
      float* out = b.filtered + view * static_cast<std::size_t>(b.stride_rows) * b.stride_cols +
                   static_cast<std::size_t>(row_a + IVOL_BAND_BORDER_BEFORE) * b.stride_cols + IVOL_BAND_BORDER_BEFORE;
      for (int i = 0; i < b.columns; ++i) out[i] = result->re[static_cast<std::size_t>(i) * kLanes + l];
      if (row_a + 1 < b.band_rows)
        for (int i = 0; i < b.columns; ++i)
          out[b.stride_cols + i] = result->im[static_cast<std::size_t>(i) * kLanes + l];
    }
  }
}

}  // namespace

bool native_filter_available() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("fma");
}

void filter_rows_native(const NativeFilterBatch& batch, unsigned threads) {
  const std::size_t pairs = static_cast<std::size_t>(batch.band_rows + 1) / 2 * batch.view_count;
  // Whole groups of sixteen pairs per thread.
  const std::size_t groups = (pairs + kLanes - 1) / kLanes;
  threads = std::max(1u, std::min<unsigned>(threads, static_cast<unsigned>(std::max<std::size_t>(groups, 1))));
  on_threads(threads, [&](unsigned t) {
    const std::size_t first = std::min(pairs, groups * t / threads * kLanes);
    const std::size_t last = std::min(pairs, groups * (t + 1) / threads * kLanes);
    if (first < last) filter_pairs(batch, first, last);
  });
}

}  // namespace ivol::recon::detail
