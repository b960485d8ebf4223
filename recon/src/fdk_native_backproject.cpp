#include "fdk_native_backproject.hpp"

#include <immintrin.h>

#include <algorithm>
#include <cmath>

#include "native_threads.hpp"

// This file is compiled with -ffp-contract=off (recon/CMakeLists.txt): every
// fused multiply-add below is written out, where the kernel's compiler fuses.

namespace ivol::recon::detail {
namespace {

constexpr int kBatch = IVOL_BACKPROJECT_BATCH;
constexpr int kBorderBefore = IVOL_BAND_BORDER_BEFORE;
constexpr int kBorderAfter = IVOL_BAND_BORDER_AFTER;
constexpr std::uint32_t kLanes = NativeBackprojector::kLanes;
// A strip is two vectors: the rows of sixteen voxels must lie within 31
// rows so that each voxel's row and the next one are among them.
constexpr int kStrip = 2 * kLanes;
constexpr std::uint32_t kTile = 16;

// What a voxel column (i, j) keeps along k for one view: the kernel's
// per-view scalars, computed with the kernel's roundings.
struct ColumnView {
  float column_frac;
  float weight;
  float row_at_zero;
  float row_step;
  int column_index;  // band column of the left pixel, border included
};

__attribute__((target("avx512f,fma"))) ColumnView column_view(const BackprojectView& m, float fi, float fj,
                                                              float column_limit) {
  // clang contracts a·b + c·d + e into fma(a, b, c·d) + e.
  const float w = __builtin_fmaf(m.depth[0], fi, m.depth[1] * fj) + m.depth[3];
  const float inv_w = 1.0F / w;
  const float projected = (__builtin_fmaf(m.column[0], fi, m.column[1] * fj) + m.column[3]) * inv_w;
  const float column = std::fmin(std::fmax(projected, -1.0F), column_limit);
  const float column_floor = std::floor(column);
  ColumnView view;
  view.column_frac = column - column_floor;
  view.weight = inv_w * inv_w;
  view.row_at_zero = (__builtin_fmaf(m.row[0], fi, m.row[1] * fj) + m.row[3]) * inv_w;
  view.row_step = m.row[2] * inv_w;
  view.column_index = static_cast<int>(column_floor) + kBorderBefore;
  return view;
}

struct BatchArgs {
  const float* transposed;  // per view [column][row]
  std::size_t plane;        // floats per view
  int stride_rows;
  float column_limit;
  float row_limit;
  float band_first;
  const BackprojectView* views;
};

BatchArgs batch_args(const float* transposed, int stride_cols, int stride_rows, int band_first_row,
                     const BackprojectView* views) {
  BatchArgs args;
  args.transposed = transposed;
  args.plane = static_cast<std::size_t>(stride_cols) * stride_rows;
  args.stride_rows = stride_rows;
  // As the kernel: clamped into the zero border, one pixel before the band
  // and up to IVOL_BAND_BORDER_AFTER after it.
  args.column_limit = static_cast<float>(stride_cols - kBorderBefore - kBorderAfter);
  args.row_limit = static_cast<float>(stride_rows - kBorderBefore - kBorderAfter);
  args.band_first = static_cast<float>(band_first_row);
  args.views = views;
  return args;
}

// A column's top and bottom samples, interpolated between detector columns,
// from the four pixels around each row (`left`: the left column of a
// transposed band, rows contiguous), where the rows span more than a strip.
__attribute__((target("avx512f,fma"))) inline void gather_top_bottom(const float* left, int stride_rows,
                                                                     __m512i row_index, __m512 column_frac, __m512& top,
                                                                     __m512& bottom) {
  const __m512i one = _mm512_set1_epi32(1);
  const __m512i right = _mm512_set1_epi32(stride_rows);
  const __m512i offset = _mm512_add_epi32(row_index, _mm512_set1_epi32(kBorderBefore));
  const __m512i below = _mm512_add_epi32(offset, one);
  const __m512 tl = _mm512_i32gather_ps(offset, left, 4);
  const __m512 tr = _mm512_i32gather_ps(_mm512_add_epi32(offset, right), left, 4);
  const __m512 bl = _mm512_i32gather_ps(below, left, 4);
  const __m512 br = _mm512_i32gather_ps(_mm512_add_epi32(below, right), left, 4);
  top = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(tr, tl), tl);
  bottom = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(br, bl), bl);
}

// Adds one batch to the voxel column whose per-view scalars are `at`:
// sixteen slices at a time, each view's sixteen rows from one strip.
__attribute__((target("avx512f,fma"))) inline void backproject_column(const BatchArgs& a, const ColumnView* at,
                                                                      float* column, std::uint32_t depth,
                                                                      std::uint32_t k_first) {
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512i one = _mm512_set1_epi32(1);
  const __m512 minus_one = _mm512_set1_ps(-1.0F);
  const __m512 row_limit = _mm512_set1_ps(a.row_limit);
  const __m512 band_first = _mm512_set1_ps(a.band_first);
  for (std::uint32_t k = 0; k < depth; k += kLanes) {
    // Slice indices as floats, exactly (they are far below 2^24).
    const __m512 fk = _mm512_cvtepi32_ps(_mm512_add_epi32(_mm512_set1_epi32(static_cast<int>(k_first + k)), lane));
    __m512 sum = _mm512_setzero_ps();
    for (int v = 0; v < kBatch; ++v) {
      const ColumnView& c = at[v];
      __m512 row = _mm512_fmadd_ps(fk, _mm512_set1_ps(c.row_step), _mm512_set1_ps(c.row_at_zero));
      row = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(row, band_first), minus_one), row_limit);
      const __m512i row_index = _mm512_cvt_roundps_epi32(row, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
      const __m512 row_frac = _mm512_sub_ps(row, _mm512_cvtepi32_ps(row_index));
      const __m512 column_frac = _mm512_set1_ps(c.column_frac);
      // Rows are monotonic along k: the first or the last lane is lowest.
      const int first = _mm_cvtsi128_si32(_mm512_castsi512_si128(row_index));
      const int last = _mm_extract_epi32(_mm512_extracti32x4_epi32(row_index, 3), 3);
      const int lowest = std::min(first, last);
      const float* left = a.transposed + static_cast<std::size_t>(v) * a.plane +
                          static_cast<std::size_t>(c.column_index) * a.stride_rows;
      __m512 top;
      __m512 bottom;
      if (std::max(first, last) - lowest < kStrip - 1) {
        // top(r) = image[r][c] + frac·(image[r][c+1] − image[r][c]) for 32
        // rows at once; a voxel's "top" is top(r), its "bottom" top(r+1).
        const float* strip = left + lowest + kBorderBefore;
        const float* right = strip + a.stride_rows;
        const __m512 l0 = _mm512_loadu_ps(strip);
        const __m512 l1 = _mm512_loadu_ps(strip + kLanes);
        const __m512 s0 = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(_mm512_loadu_ps(right), l0), l0);
        const __m512 s1 = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(_mm512_loadu_ps(right + kLanes), l1), l1);
        const __m512i offset = _mm512_sub_epi32(row_index, _mm512_set1_epi32(lowest));
        top = _mm512_permutex2var_ps(s0, offset, s1);
        bottom = _mm512_permutex2var_ps(s0, _mm512_add_epi32(offset, one), s1);
      } else {
        // Steep rows (fine detector rows): gather the four pixels.
        gather_top_bottom(left, a.stride_rows, row_index, column_frac, top, bottom);
      }
      const __m512 value = _mm512_fmadd_ps(row_frac, _mm512_sub_ps(bottom, top), top);
      sum = _mm512_fmadd_ps(_mm512_set1_ps(c.weight), value, sum);
    }
    _mm512_storeu_ps(column + k, _mm512_add_ps(_mm512_loadu_ps(column + k), sum));
  }
}

// Adds one batch to the columns of rows [j_begin, j_end), in tiles of
// kTile² columns: a tile projects onto a few dozen detector columns per
// view, so the part of the band it reads stays in L2.
__attribute__((target("avx512f,fma"))) void backproject_rows(const BatchArgs& a, float* columns, std::uint32_t nx,
                                                             std::uint32_t depth, std::uint32_t k_first,
                                                             std::uint32_t j_begin, std::uint32_t j_end) {
  ColumnView at[kBatch];
  for (std::uint32_t j0 = j_begin; j0 < j_end; j0 += kTile)
    for (std::uint32_t i0 = 0; i0 < nx; i0 += kTile)
      for (std::uint32_t j = j0; j < std::min(j_end, j0 + kTile); ++j)
        for (std::uint32_t i = i0; i < std::min(nx, i0 + kTile); ++i) {
          for (int v = 0; v < kBatch; ++v)
            at[v] = column_view(a.views[v], static_cast<float>(i), static_cast<float>(j), a.column_limit);
          backproject_column(a, at, columns + (std::size_t{j} * nx + i) * depth, depth, k_first);
        }
}

constexpr int kDepth = IVOL_BACKPROJECT_DEPTH;
constexpr int kRun = IVOL_FINE_RUN;
// Slabs up to this many slices are summed as fine tasks (start_slab);
// measured in bench/RESULTS.md, "Thin dense slabs on the CPU".
constexpr std::uint32_t kThinSlab = 32;

// Lane x's scalar in vector lanes 0-7 and lane y's in lanes 8-15.
__attribute__((target("avx512f"))) inline __m512 lane_pair(const float (&lanes)[kRun], int x, int y) {
  return _mm512_mask_blend_ps(0xFF00, _mm512_set1_ps(lanes[x]), _mm512_set1_ps(lanes[y]));
}

// Sixteen rows of a band's column from `lowest` on, interpolated towards
// the next column by `frac` (the kernel's top(r) for each row r).
__attribute__((target("avx512f,fma"))) inline __m512 strip_of(const float* band, int stride_rows, int column,
                                                              int lowest, float frac) {
  const float* strip = band + static_cast<std::size_t>(column) * stride_rows + lowest + kBorderBefore;
  const __m512 left = _mm512_loadu_ps(strip);
  return _mm512_fmadd_ps(_mm512_set1_ps(frac), _mm512_sub_ps(_mm512_loadu_ps(strip + stride_rows), left), left);
}
static_assert(kDepth == 8 && kRun == 16, "one vector holds a task's voxels along k twice over");

// The kernels' projection of sixteen points (fi, fj) into one view:
// column_view's operations in vector form (the column clamped as
// fmin(fmax(p, −1), limit): max_ps returns −1 for a NaN p as fmax does).
struct LaneViews {
  __m512 inv_w, column, column_floor, row_at_zero, row_step;
};

__attribute__((target("avx512f,fma"))) inline LaneViews project_lanes(const BackprojectView& m, __m512 fi, __m512 fj,
                                                                      __m512 column_limit) {
  auto affine = [&](const float* r) __attribute__((target("avx512f,fma"))) {
    return _mm512_add_ps(_mm512_fmadd_ps(_mm512_set1_ps(r[0]), fi, _mm512_mul_ps(_mm512_set1_ps(r[1]), fj)),
                         _mm512_set1_ps(r[3]));
  };
  LaneViews c;
  c.inv_w = _mm512_div_ps(_mm512_set1_ps(1.0F), affine(m.depth));
  c.column =
      _mm512_min_ps(_mm512_max_ps(_mm512_mul_ps(affine(m.column), c.inv_w), _mm512_set1_ps(-1.0F)), column_limit);
  c.column_floor = _mm512_roundscale_ps(c.column, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
  c.row_at_zero = _mm512_mul_ps(affine(m.row), c.inv_w);
  c.row_step = _mm512_mul_ps(_mm512_set1_ps(m.row[2]), c.inv_w);
  return c;
}

// Adds one batch to fine tasks [begin, end): kernels/fdk_backproject.cl's
// fdk_backproject_fine operation for operation. A lane holds voxel d = lane
// mod 8 of a task's stack (the upper eight repeat the lower), so that a
// column's eight rows come from one 16-row strip like a dense column's.
__attribute__((target("avx512f,fma"))) void backproject_fine_tasks(const BatchArgs& a, const FineTask* tasks,
                                                                   std::size_t begin, std::size_t end, float* sums) {
  const __m512i one = _mm512_set1_epi32(1);
  const __m512 minus_one = _mm512_set1_ps(-1.0F);
  const __m512 row_limit = _mm512_set1_ps(a.row_limit);
  const __m512 band_first = _mm512_set1_ps(a.band_first);
  const __m512 depth = _mm512_setr_ps(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7);
  // The per-view scalars of a task's sixteen lanes, [view][lane]: column_view
  // for all lanes at once, the same operations in vector form.
  alignas(64) float lane_frac[kBatch][kRun], lane_weight[kBatch][kRun], lane_row0[kBatch][kRun],
      lane_step[kBatch][kRun];
  alignas(64) int lane_column[kBatch][kRun];
  alignas(64) float part[kLanes];
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512 column_limit = _mm512_set1_ps(a.column_limit);
  for (std::size_t t = begin; t < end; ++t) {
    const FineTask& task = tasks[t];
    // The kernel: fk = task.k + (float)d * task.step_k, fused.
    const __m512 fk = _mm512_fmadd_ps(depth, _mm512_set1_ps(task.step_k), _mm512_set1_ps(task.k));
    const int run_i = static_cast<int>(task.run_i);
    // fi = task.i + (float)(x & (run_i − 1)) · step_i and fj = task.j +
    // (float)(x / run_i) · step_j, fused, for the sixteen lanes x.
    const __m512i x_i = _mm512_and_si512(lane, _mm512_set1_epi32(run_i - 1));
    const __m512i x_j = _mm512_srlv_epi32(lane, _mm512_set1_epi32(__builtin_ctz(static_cast<unsigned>(run_i))));
    const __m512 fi = _mm512_fmadd_ps(_mm512_cvtepi32_ps(x_i), _mm512_set1_ps(task.step_i), _mm512_set1_ps(task.i));
    const __m512 fj = _mm512_fmadd_ps(_mm512_cvtepi32_ps(x_j), _mm512_set1_ps(task.step_j), _mm512_set1_ps(task.j));
    for (int v = 0; v < kBatch; ++v) {
      const LaneViews c = project_lanes(a.views[v], fi, fj, column_limit);
      _mm512_store_ps(lane_frac[v], _mm512_sub_ps(c.column, c.column_floor));
      _mm512_store_ps(lane_weight[v], _mm512_mul_ps(c.inv_w, c.inv_w));
      _mm512_store_ps(lane_row0[v], c.row_at_zero);
      _mm512_store_ps(lane_step[v], c.row_step);
      _mm512_store_si512(lane_column[v],
                         _mm512_add_epi32(_mm512_cvttps_epi32(c.column_floor), _mm512_set1_epi32(kBorderBefore)));
    }
    // Only the lanes that hold points of the brick: the kernel computes all
    // sixteen, and the host never reads the rest (a brick of 2³ voxels fills
    // four of a task's sixteen lanes).
    const int along_i = static_cast<int>(task.count & 0xFF), along_j = static_cast<int>((task.count >> 8) & 0xFF);
    int used[kRun];
    int used_count = 0;
    for (int x = 0; x < kRun; ++x)
      if ((x & (run_i - 1)) < along_i && x / run_i < along_j) used[used_count++] = x;
    // Two lanes a vector: lanes 0-7 hold lane x's eight points along k, lanes
    // 8-15 lane y's (x again when x is the last).
    const __mmask16 upper = 0xFF00;
    for (int u = 0; u < used_count; u += 2) {
      const int x = used[u], y = u + 1 < used_count ? used[u + 1] : x;
      __m512 sum = _mm512_setzero_ps();
      for (int v = 0; v < kBatch; ++v) {
        __m512 row = _mm512_fmadd_ps(fk, lane_pair(lane_step[v], x, y), lane_pair(lane_row0[v], x, y));
        row = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(row, band_first), minus_one), row_limit);
        const __m512i row_index = _mm512_cvt_roundps_epi32(row, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
        const __m512 row_frac = _mm512_sub_ps(row, _mm512_cvtepi32_ps(row_index));
        // Rows are monotonic along k: each half's first or last lane is lowest.
        const int x_first = _mm_cvtsi128_si32(_mm512_castsi512_si128(row_index));
        const int x_last = _mm_extract_epi32(_mm512_extracti32x4_epi32(row_index, 1), 3);
        const int y_first = _mm_cvtsi128_si32(_mm512_extracti32x4_epi32(row_index, 2));
        const int y_last = _mm_extract_epi32(_mm512_extracti32x4_epi32(row_index, 3), 3);
        const int x_lowest = std::min(x_first, x_last), y_lowest = std::min(y_first, y_last);
        const float* band = a.transposed + static_cast<std::size_t>(v) * a.plane;
        const int x_column = lane_column[v][x], y_column = lane_column[v][y];
        __m512 top;
        __m512 bottom;
        if (std::max(x_first, x_last) - x_lowest < static_cast<int>(kLanes) - 1 &&
            std::max(y_first, y_last) - y_lowest < static_cast<int>(kLanes) - 1) {
          // A 16-row strip for each lane, interpolated between its columns.
          const __m512 sx = strip_of(band, a.stride_rows, x_column, x_lowest, lane_frac[v][x]);
          const __m512 sy = strip_of(band, a.stride_rows, y_column, y_lowest, lane_frac[v][y]);
          const __m512i offset = _mm512_sub_epi32(
              row_index, _mm512_mask_blend_epi32(upper, _mm512_set1_epi32(x_lowest), _mm512_set1_epi32(y_lowest - 16)));
          top = _mm512_permutex2var_ps(sx, offset, sy);
          bottom = _mm512_permutex2var_ps(sx, _mm512_add_epi32(offset, one), sy);
        } else {
          // Steep rows: gather the four pixels of each lane.
          const __m512i column_at = _mm512_mask_blend_epi32(upper, _mm512_set1_epi32(x_column * a.stride_rows),
                                                            _mm512_set1_epi32(y_column * a.stride_rows));
          const __m512i at = _mm512_add_epi32(column_at, _mm512_add_epi32(row_index, _mm512_set1_epi32(kBorderBefore)));
          const __m512i right = _mm512_set1_epi32(a.stride_rows);
          const __m512i below = _mm512_add_epi32(at, one);
          const __m512 column_frac = lane_pair(lane_frac[v], x, y);
          const __m512 tl = _mm512_i32gather_ps(at, band, 4);
          const __m512 tr = _mm512_i32gather_ps(_mm512_add_epi32(at, right), band, 4);
          const __m512 bl = _mm512_i32gather_ps(below, band, 4);
          const __m512 br = _mm512_i32gather_ps(_mm512_add_epi32(below, right), band, 4);
          top = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(tr, tl), tl);
          bottom = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(br, bl), bl);
        }
        const __m512 value = _mm512_fmadd_ps(row_frac, _mm512_sub_ps(bottom, top), top);
        sum = _mm512_fmadd_ps(lane_pair(lane_weight[v], x, y), value, sum);
      }
      _mm512_store_ps(part, sum);
      float* out = sums + t * (kDepth * kRun);
      for (int d = 0; d < kDepth; ++d) out[d * kRun + x] += part[d];
      if (y != x)
        for (int d = 0; d < kDepth; ++d) out[d * kRun + y] += part[kDepth + d];
    }
  }
}

// Adds one batch to lone coarse voxels [begin, end), sixteen at a time:
// kernels/fdk_backproject.cl's fdk_backproject_centre (octants == 1) or
// fdk_backproject_octants (8), sample_view operation for operation, from
// the band as filtered (rows contiguous; four gathers a sample, as the
// kernel's).
__attribute__((target("avx512f,fma"))) void backproject_lone_tasks(const BatchArgs& a, const float* filtered,
                                                                   int stride_cols, const CoarseTask* tasks,
                                                                   std::size_t begin, std::size_t end, int octants,
                                                                   float* sums) {
  const __m512 minus_one = _mm512_set1_ps(-1.0F);
  const __m512 column_limit = _mm512_set1_ps(a.column_limit);
  const __m512 row_limit = _mm512_set1_ps(a.row_limit);
  const __m512 band_first = _mm512_set1_ps(a.band_first);
  const __m512i border = _mm512_set1_epi32(kBorderBefore);
  const __m512i stride = _mm512_set1_epi32(stride_cols);
  const __m512i one = _mm512_set1_epi32(1);
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const std::size_t plane = a.plane;
  for (std::size_t t0 = begin; t0 < end; t0 += kLanes) {
    const int count = static_cast<int>(std::min<std::size_t>(kLanes, end - t0));
    const __mmask16 live = static_cast<__mmask16>((1u << count) - 1);
    // The tasks' fields as vectors (CoarseTask: 8 floats; lanes past the
    // end repeat the first task).
    const __m512i index = _mm512_mullo_epi32(_mm512_mask_blend_epi32(live, _mm512_setzero_si512(), lane),
                                             _mm512_set1_epi32(sizeof(CoarseTask) / sizeof(float)));
    const auto* fields = reinterpret_cast<const float*>(tasks + t0);
    const __m512 ci = _mm512_i32gather_ps(index, fields + 0, 4);
    const __m512 cj = _mm512_i32gather_ps(index, fields + 1, 4);
    const __m512 ck = _mm512_i32gather_ps(index, fields + 2, 4);
    const __m512 qi = _mm512_i32gather_ps(index, fields + 3, 4);
    const __m512 qj = _mm512_i32gather_ps(index, fields + 4, 4);
    const __m512 qk = _mm512_i32gather_ps(index, fields + 5, 4);
    const __m512 zero = _mm512_setzero_ps();
    __m512 sum = _mm512_setzero_ps();
    for (int v = 0; v < kBatch; ++v) {
      const BackprojectView& m = a.views[v];
      const float* image = filtered + static_cast<std::size_t>(v) * plane;
      for (int octant = 0; octant < octants; ++octant) {
        // fi = task.i + (OCTANTS == 1 ? 0.0f : ±quarter_i), and so on.
        const __m512 fi = _mm512_add_ps(ci, octants == 1 ? zero : (octant & 1) ? qi : _mm512_mul_ps(qi, minus_one));
        const __m512 fj = _mm512_add_ps(cj, octants == 1 ? zero : (octant & 2) ? qj : _mm512_mul_ps(qj, minus_one));
        const __m512 fk = _mm512_add_ps(ck, octants == 1 ? zero : (octant & 4) ? qk : _mm512_mul_ps(qk, minus_one));
        const LaneViews c = project_lanes(m, fi, fj, column_limit);
        const __m512 column_floor = c.column_floor;
        const __m512 column_frac = _mm512_sub_ps(c.column, column_floor);
        const __m512 inv_w = c.inv_w;
        __m512 row = _mm512_fmadd_ps(fk, c.row_step, c.row_at_zero);
        row = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(row, band_first), minus_one), row_limit);
        const __m512 row_floor = _mm512_roundscale_ps(row, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
        const __m512 row_frac = _mm512_sub_ps(row, row_floor);
        const __m512i at =
            _mm512_add_epi32(_mm512_mullo_epi32(_mm512_add_epi32(_mm512_cvttps_epi32(row_floor), border), stride),
                             _mm512_add_epi32(_mm512_cvttps_epi32(column_floor), border));
        const __m512 tl = _mm512_i32gather_ps(at, image, 4);
        const __m512 tr = _mm512_i32gather_ps(_mm512_add_epi32(at, one), image, 4);
        const __m512 bl = _mm512_i32gather_ps(_mm512_add_epi32(at, stride), image, 4);
        const __m512 br = _mm512_i32gather_ps(_mm512_add_epi32(_mm512_add_epi32(at, stride), one), image, 4);
        const __m512 top = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(tr, tl), tl);
        const __m512 bottom = _mm512_fmadd_ps(column_frac, _mm512_sub_ps(br, bl), bl);
        const __m512 value =
            _mm512_mul_ps(_mm512_mul_ps(inv_w, inv_w), _mm512_fmadd_ps(row_frac, _mm512_sub_ps(bottom, top), top));
        sum = _mm512_add_ps(sum, value);
      }
    }
    alignas(64) float part[kLanes];
    _mm512_store_ps(part, _mm512_div_ps(sum, _mm512_set1_ps(static_cast<float>(octants))));
    for (int l = 0; l < count; ++l) sums[t0 + l] += part[l];
  }
}

}  // namespace

bool native_backprojection_available() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("fma");
}

NativeBackprojector::NativeBackprojector(unsigned threads) : threads_(std::max(1u, threads)) {}

void NativeBackprojector::start_slab(std::uint32_t nx, std::uint32_t ny, std::uint32_t k_first, std::uint32_t slices) {
  nx_ = nx;
  ny_ = ny;
  k_first_ = k_first;
  slices_ = slices;
  depth_ = (slices + kLanes - 1) / kLanes * kLanes;
  tiles_i_ = (nx + kRun - 1) / kRun;
  stacks_ = (slices + kDepth - 1) / kDepth;
  // Tasks where they hold no more floats than the columns would (so the
  // slab plan's count of the columns still bounds them) and the slab is
  // thin enough that the columns' per-view scalars would dominate.
  const std::uint64_t column_floats = std::uint64_t{nx} * ny * depth_;
  const std::uint64_t task_floats = std::uint64_t{tiles_i_} * kRun * ny * stacks_ * kDepth;
  thin_ = slices <= kThinSlab && task_floats <= column_floats;
  if (thin_) {
    std::vector<float>().swap(columns_);
    task_sums_.assign(task_floats, 0.0F);
  } else {
    std::vector<float>().swap(task_sums_);
    columns_.assign(column_floats, 0.0F);
  }
}

void NativeBackprojector::transpose(const float* filtered, int stride_cols, int stride_rows) {
  const std::size_t plane = static_cast<std::size_t>(stride_cols) * stride_rows;
  // A strip read at the last column of the last view may run kStrip floats
  // past its plane; those lanes are never selected.
  transposed_.resize(kBatch * plane + kStrip);
  std::fill(transposed_.end() - kStrip, transposed_.end(), 0.0F);
  on_threads(threads_, [&](unsigned t) {
    for (int v = static_cast<int>(t); v < kBatch; v += static_cast<int>(threads_)) {
      const float* in = filtered + v * plane;
      float* out = transposed_.data() + v * plane;
      for (int r0 = 0; r0 < stride_rows; r0 += 16)
        for (int c = 0; c < stride_cols; ++c)
          for (int r = r0; r < std::min(r0 + 16, stride_rows); ++r)
            out[static_cast<std::size_t>(c) * stride_rows + r] = in[static_cast<std::size_t>(r) * stride_cols + c];
    }
  });
}

void NativeBackprojector::add_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                                    const BackprojectView* views) {
  transpose(filtered, stride_cols, stride_rows);
  const BatchArgs args = batch_args(transposed_.data(), stride_cols, stride_rows, band_first_row, views);
  if (thin_) {
    // Task t = (stack·ny + j)·tiles_i + tile: columns [16·tile, 16·tile + 16)
    // of row j, slices [8·stack, 8·stack + 8) of the slab, made a few
    // hundred at a time (a slab's tasks are never all held).
    const std::size_t tasks = std::size_t{stacks_} * ny_ * tiles_i_;
    on_threads(threads_, [&](unsigned t) {
      constexpr std::size_t kChunk = 256;
      FineTask chunk[kChunk];
      const std::size_t first = tasks * t / threads_, last = tasks * (t + 1) / threads_;
      for (std::size_t c0 = first; c0 < last; c0 += kChunk) {
        const std::size_t n = std::min(kChunk, last - c0);
        for (std::size_t c = 0; c < n; ++c) {
          const std::size_t task = c0 + c;
          const auto tile = static_cast<std::uint32_t>(task % tiles_i_);
          const auto j = static_cast<std::uint32_t>(task / tiles_i_ % ny_);
          const auto stack = static_cast<std::uint32_t>(task / (std::size_t{tiles_i_} * ny_));
          const std::uint32_t along_i = std::min<std::uint32_t>(kRun, nx_ - tile * kRun);
          const std::uint32_t along_k = std::min<std::uint32_t>(kDepth, slices_ - stack * kDepth);
          FineTask& f = chunk[c];
          f.i = static_cast<float>(tile * kRun);
          f.j = static_cast<float>(j);
          f.k = static_cast<float>(k_first_ + stack * kDepth);
          f.step_i = f.step_j = f.step_k = 1.0F;
          f.run_i = kRun;
          f.count = along_i | (1u << 8) | (along_k << 16);
        }
        backproject_fine_tasks(args, chunk, 0, n, task_sums_.data() + c0 * (kDepth * kRun));
      }
    });
    return;
  }
  on_threads(threads_, [&](unsigned t) {
    const std::uint32_t j_begin = static_cast<std::uint32_t>(std::uint64_t{ny_} * t / threads_);
    const std::uint32_t j_end = static_cast<std::uint32_t>(std::uint64_t{ny_} * (t + 1) / threads_);
    backproject_rows(args, columns_.data(), nx_, depth_, k_first_, j_begin, j_end);
  });
}

void NativeBackprojector::add_fine_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                                         const BackprojectView* views, const FineTask* tasks, std::size_t task_count,
                                         float* sums) {
  transpose(filtered, stride_cols, stride_rows);
  const BatchArgs args = batch_args(transposed_.data(), stride_cols, stride_rows, band_first_row, views);
  on_threads(threads_, [&](unsigned t) {
    backproject_fine_tasks(args, tasks, task_count * t / threads_, task_count * (t + 1) / threads_, sums);
  });
}

void NativeBackprojector::add_lone_batch(const float* filtered, int stride_cols, int stride_rows, int band_first_row,
                                         const BackprojectView* views, const CoarseTask* tasks, std::size_t task_count,
                                         int octants, float* sums) const {
  const BatchArgs args = batch_args(nullptr, stride_cols, stride_rows, band_first_row, views);
  // Whole groups of sixteen tasks per thread.
  const std::size_t groups = (task_count + kLanes - 1) / kLanes;
  on_threads(threads_, [&](unsigned t) {
    const std::size_t first = std::min(task_count, groups * t / threads_ * kLanes);
    const std::size_t last = std::min(task_count, groups * (t + 1) / threads_ * kLanes);
    if (first < last) backproject_lone_tasks(args, filtered, stride_cols, tasks, first, last, octants, sums);
  });
}

void NativeBackprojector::finish_slab(std::vector<float>& out) const {
  out.resize(std::size_t{nx_} * ny_ * slices_);
  if (thin_) {
    on_threads(threads_, [&](unsigned t) {
      const std::uint32_t j_begin = static_cast<std::uint32_t>(std::uint64_t{ny_} * t / threads_);
      const std::uint32_t j_end = static_cast<std::uint32_t>(std::uint64_t{ny_} * (t + 1) / threads_);
      for (std::uint32_t k = 0; k < slices_; ++k)
        for (std::uint32_t j = j_begin; j < j_end; ++j) {
          const float* task = task_sums_.data() + ((std::size_t{k / kDepth} * ny_ + j) * tiles_i_) * (kDepth * kRun) +
                              (k % kDepth) * kRun;
          float* row = out.data() + (std::size_t{k} * ny_ + j) * nx_;
          for (std::uint32_t i = 0; i < nx_; ++i) row[i] = task[(i / kRun) * (kDepth * kRun) + i % kRun];
        }
    });
    return;
  }
  on_threads(threads_, [&](unsigned t) {
    const std::uint32_t j_begin = static_cast<std::uint32_t>(std::uint64_t{ny_} * t / threads_);
    const std::uint32_t j_end = static_cast<std::uint32_t>(std::uint64_t{ny_} * (t + 1) / threads_);
    // Sixteen columns at a time, so that the columns stay in cache while
    // their slices are written out.
    for (std::uint32_t j = j_begin; j < j_end; ++j)
      for (std::uint32_t i0 = 0; i0 < nx_; i0 += kLanes) {
        const std::uint32_t i_end = std::min(nx_, i0 + kLanes);
        for (std::uint32_t k = 0; k < slices_; ++k) {
          float* row = out.data() + (std::size_t{k} * ny_ + j) * nx_;
          for (std::uint32_t i = i0; i < i_end; ++i) row[i] = columns_[(std::size_t{j} * nx_ + i) * depth_ + k];
        }
      }
  });
}

}  // namespace ivol::recon::detail
