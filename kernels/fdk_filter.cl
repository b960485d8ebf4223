/* FDK pre-weighting and ramp filtering of detector rows.
 *
 * One work-group filters a pair of rows of one view: the two real rows are
 * packed as the real and imaginary parts of one complex sequence, zero-padded
 * to n = 2^log2n ≥ 2·columns (no circular wrap-around), transformed with a
 * radix-2 Stockham FFT, multiplied by the real and even response of the
 * windowed ramp (so the two rows stay separate), and transformed back.
 * Rows are paired by their global index, so a row gives the same bits
 * whatever band it is filtered in. The FFT scratch lives in local memory, or
 * in global memory (IVOL_FFT_IN_GLOBAL) when n is too long for the device's
 * local memory. On CPU devices with AVX-512, fdk_weight_rows does the
 * weighting and recon/src/fdk_native_filter.cpp the rest, operation for
 * operation: a change here must be made there too (test_fdk_native). */

#ifdef IVOL_FFT_IN_GLOBAL
#define FFT_SPACE __global
#else
#define FFT_SPACE __local
#endif

static float parker_weight(float beta, float gamma, float delta) {
  /* Parker (1982), with conjugate rays at (beta + pi + 2 gamma, -gamma). */
  const float quarter_pi = 0.785398163397448f;
  if (beta < 0.0f) return 0.0f;
  if (beta < 2.0f * (delta - gamma)) {
    const float s = sin(quarter_pi * beta / (delta - gamma));
    return s * s;
  }
  if (beta < M_PI_F - 2.0f * gamma) return 1.0f;
  if (beta <= M_PI_F + 2.0f * delta) {
    const float s = sin(quarter_pi * (M_PI_F + 2.0f * delta - beta) / (delta + gamma));
    return s * s;
  }
  return 0.0f;
}

/* Radix-2 Stockham passes from src; returns the buffer holding the result. */
/* Cosine, distance (and Parker) weights of pixel (column i, detector row
 * `row`) of a view: shared by fdk_filter_rows and fdk_weight_rows, so that
 * the native FFT path starts from the same bits. */
static float weighted(const FilterView fv, float sample, int i, int row) {
  const float v = fv.v_first + (float)row * fv.pitch_v - fv.foot_v;
  const float du = fv.u_first + (float)i * fv.pitch_u - fv.foot_u;
  float weight = fv.scale;
  if (fv.parker_delta >= 0.0f) {
    const float gamma = -fv.parker_sign * atan(du / fv.sdd);
    weight *= parker_weight(fv.parker_beta, gamma, fv.parker_delta);
  }
  const float base = fv.sdd * fv.sdd + du * du;
  return sample * weight * fv.sdd * rsqrt(base + v * v);
}

static FFT_SPACE float2* stockham(FFT_SPACE float2* src, FFT_SPACE float2* dst, __global const float2* twiddles,
                                  int log2n, float direction, int lid, int lsize) {
  const int half_n = 1 << (log2n - 1);
  for (int stage = 0; stage < log2n; ++stage) {
    const int span = 1 << stage;
    for (int j = lid; j < half_n; j += lsize) {
      const int k = j & (span - 1);
      const float2 a = src[j];
      const float2 b = src[j + half_n];
      float2 w = twiddles[k << (log2n - 1 - stage)];
      w.y *= direction;
      const float2 t = (float2)(b.x * w.x - b.y * w.y, b.x * w.y + b.y * w.x);
      const int out = ((j - k) << 1) + k;
      dst[out] = a + t;
      dst[out + span] = a - t;
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    FFT_SPACE float2* swap = src;
    src = dst;
    dst = swap;
  }
  return src;
}

/* The first step of fdk_filter_rows alone, in place: pixel (i, r) of the
 * batch's view v weighted exactly as fdk_filter_rows weights it, for CPU
 * devices whose FFTs then run in native code (recon/src/fdk_native_filter.cpp,
 * which mirrors the rest of fdk_filter_rows). Global size (columns,
 * band_rows, views in the batch). */
__kernel void fdk_weight_rows(__global float* raw, __global const FilterView* views, int view_offset, int columns,
                              int band_rows, int band_first_row) {
  const int i = get_global_id(0);
  const int r = get_global_id(1);
  const int view = get_global_id(2);
  __global float* image = raw + (size_t)view * (size_t)band_rows * (size_t)columns;
  image[r * columns + i] = weighted(views[view_offset + view], image[r * columns + i], i, band_first_row + r);
}

/* Global size: (local size × row pairs, views in the batch). raw holds the
 * batch's images of band_rows × columns line integrals, filtered the same
 * inside the zero border of IVOL_BAND_BORDER_* (stride_cols ≥ columns + 3);
 * views[view_offset + v] describes the batch's view v. */
__kernel void fdk_filter_rows(__global const float* raw, __global float* filtered, __global const FilterView* views,
                              int view_offset, __global const float* response, __global const float2* twiddles, int columns,
                              int band_rows, int band_first_row, int log2n, int stride_cols, int stride_rows,
                              FFT_SPACE float2* scratch) {
  const int lid = get_local_id(0);
  const int lsize = get_local_size(0);
  const int pair = get_group_id(0);
  const int view = get_global_id(1);
  const int n = 1 << log2n;
  /* The band starts on an even detector row, so band rows 2p and 2p+1 are a
   * pair in the detector's numbering too. */
  const int row_a = 2 * pair;
  const int row_b = row_a + 1;
#ifdef IVOL_FFT_IN_GLOBAL
  scratch += (size_t)(view * get_num_groups(0) + pair) * (size_t)(2 * n);
#endif
  FFT_SPACE float2* buffer_a = scratch;
  FFT_SPACE float2* buffer_b = scratch + n;
  const FilterView fv = views[view_offset + view];
  __global const float* image = raw + (size_t)view * (size_t)band_rows * (size_t)columns;

  /* From the detector's row index, not the band's: same bits in every band. */
  for (int i = lid; i < n; i += lsize) {
    float2 value = (float2)(0.0f, 0.0f);
    if (i < columns) {
      value.x = weighted(fv, image[row_a * columns + i], i, band_first_row + row_a);
      if (row_b < band_rows) value.y = weighted(fv, image[row_b * columns + i], i, band_first_row + row_b);
    }
    buffer_a[i] = value;
  }
  barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);

  FFT_SPACE float2* spectrum = stockham(buffer_a, buffer_b, twiddles, log2n, 1.0f, lid, lsize);
  FFT_SPACE float2* other = spectrum == buffer_a ? buffer_b : buffer_a;
  for (int i = lid; i < n; i += lsize) spectrum[i] *= response[i];
  barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
  FFT_SPACE float2* result = stockham(spectrum, other, twiddles, log2n, -1.0f, lid, lsize);

  __global float* out = filtered + (size_t)view * (size_t)stride_rows * (size_t)stride_cols;
  __global float* out_a = out + (size_t)(row_a + IVOL_BAND_BORDER_BEFORE) * stride_cols + IVOL_BAND_BORDER_BEFORE;
  for (int i = lid; i < columns; i += lsize) {
    const float2 value = result[i];
    out_a[i] = value.x;
    if (row_b < band_rows) out_a[stride_cols + i] = value.y;
  }
}
