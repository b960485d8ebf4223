/* Voxel-driven FDK backprojection with bilinear interpolation.
 *
 * A work-item adds one batch of IVOL_BACKPROJECT_BATCH views to
 * IVOL_BACKPROJECT_DEPTH voxels stacked along k. Both loops have constant
 * trip counts, so compilers unroll them and the body has no loop left: PoCL
 * then vectorises across neighbouring work-items (along i), and GPUs keep
 * everything in registers. For a circular scan a voxel column (i, j) keeps
 * its detector column and distance weight along k, so they are computed once
 * per view for the whole stack; only the detector row moves with k. The
 * order of accumulation is fixed, so a voxel's bits do not depend on the slab
 * it was computed in. A batch short of views is padded with views whose
 * rays miss the detector. On CPU devices with AVX-512 the dense slabs and
 * the structure kernels below take recon/src/fdk_native_backproject.cpp
 * instead, which repeats this arithmetic operation for operation (clang's
 * fused multiply-adds included): a change here must be made there too, and
 * test_fdk_native compares the bits of the two. */
__kernel void fdk_backproject(__global float* restrict slab, int row_stride, int ny, int k_first,
                              __global const float* restrict filtered, int stride_cols, int stride_rows,
                              int band_first_row, __global const BackprojectView* restrict views, int view_offset) {
  const int i = get_global_id(0);
  const int j = get_global_id(1);
  const int k_stack = get_global_id(2) * IVOL_BACKPROJECT_DEPTH;
  /* No bounds test: the host pads the slab's rows to whole work-groups and
   * launches exactly ny rows, so the loop PoCL vectorises has no mask. */
  const float fi = (float)i;
  const float fj = (float)j;
  /* Positions outside the band are clamped into its zero border: one pixel
   * before the first stored one, up to IVOL_BAND_BORDER_AFTER after. The
   * floor is taken before the border offset is added as an integer, and the
   * band's first row is subtracted from a float of larger magnitude, so both
   * steps are exact and a voxel's bits do not depend on the band. */
  const float column_limit = (float)(stride_cols - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);
  const float row_limit = (float)(stride_rows - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);
  const float band_first = (float)band_first_row;
  const size_t plane = (size_t)stride_cols * (size_t)stride_rows;

  float sum[IVOL_BACKPROJECT_DEPTH];
#pragma unroll
  for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) sum[d] = 0.0f;

#pragma unroll
  for (int v = 0; v < IVOL_BACKPROJECT_BATCH; ++v) {
    const BackprojectView m = views[view_offset + v];
    const float w = m.depth[0] * fi + m.depth[1] * fj + m.depth[3];
    const float inv_w = 1.0f / w;
    const float column = clamp((m.column[0] * fi + m.column[1] * fj + m.column[3]) * inv_w, -1.0f, column_limit);
    const float column_floor = floor(column);
    const float column_frac = column - column_floor;
    const float weight = inv_w * inv_w;
    const float row_at_zero = (m.row[0] * fi + m.row[1] * fj + m.row[3]) * inv_w;
    const float row_step = m.row[2] * inv_w;
    /* 32-bit offsets within one view's band (checked on the host): on CPUs
     * they halve the width of the gathers. */
    __global const float* image = filtered + (size_t)v * plane;
    const int column_index = (int)column_floor + IVOL_BAND_BORDER_BEFORE;
#pragma unroll
    for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) {
      const float fk = (float)(k_first + k_stack + d);
      const float row = clamp((row_at_zero + fk * row_step) - band_first, -1.0f, row_limit);
      const int row_index = convert_int_rtn(row); /* floor, exactly, in one conversion */
      const float row_frac = row - (float)row_index;
      const int at = (row_index + IVOL_BAND_BORDER_BEFORE) * stride_cols + column_index;
      const float top = image[at] + column_frac * (image[at + 1] - image[at]);
      const float bottom = image[at + stride_cols] + column_frac * (image[at + stride_cols + 1] - image[at + stride_cols]);
      sum[d] += weight * (top + row_frac * (bottom - top));
    }
  }

  __global float* voxel = slab + ((size_t)k_stack * (size_t)ny + (size_t)j) * (size_t)row_stride + (size_t)i;
  const size_t slice = (size_t)row_stride * (size_t)ny;
#pragma unroll
  for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) voxel[(size_t)d * slice] += sum[d];
}


/* One view's contribution at a point given as a fractional grid index. */
static float sample_view(BackprojectView m, float fi, float fj, float fk, __global const float* image,
                         float column_limit, float row_limit, float band_first, int stride_cols) {
  const float w = m.depth[0] * fi + m.depth[1] * fj + m.depth[3];
  const float inv_w = 1.0f / w;
  const float column = clamp((m.column[0] * fi + m.column[1] * fj + m.column[3]) * inv_w, -1.0f, column_limit);
  const float column_floor = floor(column);
  const float column_frac = column - column_floor;
  const float row_at_zero = (m.row[0] * fi + m.row[1] * fj + m.row[3]) * inv_w;
  const float row = clamp((row_at_zero + fk * (m.row[2] * inv_w)) - band_first, -1.0f, row_limit);
  const float row_floor = floor(row);
  const float row_frac = row - row_floor;
  const int at = ((int)row_floor + IVOL_BAND_BORDER_BEFORE) * stride_cols + (int)column_floor + IVOL_BAND_BORDER_BEFORE;
  const float top = image[at] + column_frac * (image[at + 1] - image[at]);
  const float bottom = image[at + stride_cols] + column_frac * (image[at + stride_cols + 1] - image[at + stride_cols]);
  return inv_w * inv_w * (top + row_frac * (bottom - top));
}

/* The dense kernel's arithmetic on a list of blocks (the full-resolution
 * bricks of a structure), written out again on purpose: moved into a shared
 * function taking the stack's sums, it made PoCL keep them in memory and stop
 * vectorising (0.1 GUPS instead of 1.1); test_fdk_structure checks that the
 * two give the same bits. Global size (IVOL_FINE_RUN, tasks): work-item
 * (x, t) sums voxel (i + x, j, k + d) of block t into
 * sums[out_offset + (t·DEPTH + d)·IVOL_FINE_RUN + x]. */
__kernel void fdk_backproject_fine(__global float* restrict sums, uint out_offset, __global const FineTask* restrict tasks,
                                   int task_count, __global const float* restrict filtered, int stride_cols,
                                   int stride_rows, int band_first_row, __global const BackprojectView* restrict views,
                                   int view_offset) {
  const int x = get_global_id(0);
  const int t = get_global_id(1);  /* launched with exactly task_count rows */
  const FineTask task = tasks[t];
  const float fi = task.i + (float)(x & (int)(task.run_i - 1)) * task.step_i;
  const float fj = task.j + (float)(x / (int)task.run_i) * task.step_j;
  const float column_limit = (float)(stride_cols - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);
  const float row_limit = (float)(stride_rows - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);
  const float band_first = (float)band_first_row;
  const size_t plane = (size_t)stride_cols * (size_t)stride_rows;
  float sum[IVOL_BACKPROJECT_DEPTH];
#pragma unroll
  for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) sum[d] = 0.0f;
#pragma unroll
  for (int v = 0; v < IVOL_BACKPROJECT_BATCH; ++v) {
    const BackprojectView m = views[view_offset + v];
    const float w = m.depth[0] * fi + m.depth[1] * fj + m.depth[3];
    const float inv_w = 1.0f / w;
    const float column = clamp((m.column[0] * fi + m.column[1] * fj + m.column[3]) * inv_w, -1.0f, column_limit);
    const float column_floor = floor(column);
    const float column_frac = column - column_floor;
    const float weight = inv_w * inv_w;
    const float row_at_zero = (m.row[0] * fi + m.row[1] * fj + m.row[3]) * inv_w;
    const float row_step = m.row[2] * inv_w;
    __global const float* image = filtered + (size_t)v * plane;
    const int column_index = (int)column_floor + IVOL_BAND_BORDER_BEFORE;
#pragma unroll
    for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) {
      const float fk = task.k + (float)d * task.step_k;
      const float row = clamp((row_at_zero + fk * row_step) - band_first, -1.0f, row_limit);
      const int row_index = convert_int_rtn(row); /* floor, exactly, in one conversion */
      const float row_frac = row - (float)row_index;
      const int at = (row_index + IVOL_BAND_BORDER_BEFORE) * stride_cols + column_index;
      const float top = image[at] + column_frac * (image[at + 1] - image[at]);
      const float bottom = image[at + stride_cols] + column_frac * (image[at + stride_cols + 1] - image[at + stride_cols]);
      sum[d] += weight * (top + row_frac * (bottom - top));
    }
  }
  __global float* out = sums + out_offset + (size_t)t * (IVOL_BACKPROJECT_DEPTH * IVOL_FINE_RUN) + x;
#pragma unroll
  for (int d = 0; d < IVOL_BACKPROJECT_DEPTH; ++d) out[d * IVOL_FINE_RUN] += sum[d];
}

/* Lone coarse voxels: the value at the centre, or the mean over the centres
 * of the eight octants. One work-item per voxel, sums[out_offset + t]. */
#define COARSE_KERNEL(name, OCTANTS)                                                                              \
  __kernel void name(__global float* restrict sums, uint out_offset, __global const CoarseTask* restrict tasks,    \
                     int task_count, __global const float* restrict filtered, int stride_cols, int stride_rows,     \
                     int band_first_row, __global const BackprojectView* restrict views, int view_offset) {        \
    const int t = get_global_id(0);                                                                                \
    if (t >= task_count) return;                                                                                   \
    const CoarseTask task = tasks[t];                                                                              \
    const float column_limit = (float)(stride_cols - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);            \
    const float row_limit = (float)(stride_rows - IVOL_BAND_BORDER_BEFORE - IVOL_BAND_BORDER_AFTER);               \
    const float band_first = (float)band_first_row;                                                                \
    const size_t plane = (size_t)stride_cols * (size_t)stride_rows;                                                \
    float sum = 0.0f;                                                                                              \
    _Pragma("unroll") for (int v = 0; v < IVOL_BACKPROJECT_BATCH; ++v) {                                          \
      const BackprojectView m = views[view_offset + v];                                                            \
      __global const float* image = filtered + (size_t)v * plane;                                                  \
      _Pragma("unroll") for (int octant = 0; octant < OCTANTS; ++octant) {                                        \
        const float fi = task.i + (OCTANTS == 1 ? 0.0f : (octant & 1) ? task.quarter_i : -task.quarter_i);        \
        const float fj = task.j + (OCTANTS == 1 ? 0.0f : (octant & 2) ? task.quarter_j : -task.quarter_j);        \
        const float fk = task.k + (OCTANTS == 1 ? 0.0f : (octant & 4) ? task.quarter_k : -task.quarter_k);        \
        sum += sample_view(m, fi, fj, fk, image, column_limit, row_limit, band_first, stride_cols);               \
      }                                                                                                            \
    }                                                                                                              \
    sums[out_offset + t] += sum / (float)OCTANTS;                                                                  \
  }

COARSE_KERNEL(fdk_backproject_centre, 1)
COARSE_KERNEL(fdk_backproject_octants, 8)

#ifndef offsetof
#define offsetof(type, member) __builtin_offsetof(type, member)
#endif

/* Reads the device's own view of the shared layouts back to the host. */
__kernel void layout_probe(__global int* out) {
  if (get_global_id(0) != 0) return;
  out[0] = (int)sizeof(FilterView);
  out[1] = (int)offsetof(FilterView, scale);
  out[2] = (int)offsetof(FilterView, sdd);
  out[3] = (int)offsetof(FilterView, foot_u);
  out[4] = (int)offsetof(FilterView, foot_v);
  out[5] = (int)offsetof(FilterView, u_first);
  out[6] = (int)offsetof(FilterView, v_first);
  out[7] = (int)offsetof(FilterView, pitch_u);
  out[8] = (int)offsetof(FilterView, pitch_v);
  out[9] = (int)offsetof(FilterView, parker_beta);
  out[10] = (int)offsetof(FilterView, parker_delta);
  out[11] = (int)offsetof(FilterView, parker_sign);
  out[12] = (int)offsetof(FilterView, reserved);
  out[13] = (int)sizeof(BackprojectView);
  out[14] = (int)offsetof(BackprojectView, column);
  out[15] = (int)offsetof(BackprojectView, row);
  out[16] = (int)offsetof(BackprojectView, depth);
  out[17] = IVOL_BAND_BORDER_BEFORE;
  out[18] = IVOL_BAND_BORDER_AFTER;
  out[19] = IVOL_BACKPROJECT_BATCH;
  out[20] = IVOL_BACKPROJECT_DEPTH;
  out[21] = (int)sizeof(FineTask);
  out[22] = (int)offsetof(FineTask, run_i);
  out[23] = (int)offsetof(FineTask, count);
  out[24] = (int)sizeof(CoarseTask);
  out[25] = (int)offsetof(CoarseTask, quarter_i);
  out[26] = (int)offsetof(CoarseTask, quarter_k);
  out[27] = (int)offsetof(CoarseTask, reserved);
}
