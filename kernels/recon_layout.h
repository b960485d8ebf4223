/* Data layouts shared by the host (compiled as C++) and the OpenCL kernels
 * (compiled as OpenCL C). Every field is 4 bytes wide and naturally aligned,
 * so both compilers lay the structs out identically without packing pragmas;
 * the host checks sizes and offsets with static_assert and a test reads the
 * device's own offsetof values back (tests/test_fdk.cpp, LayoutAgrees). */
#ifndef IVOL_RECON_LAYOUT_H
#define IVOL_RECON_LAYOUT_H

#ifdef __OPENCL_VERSION__
typedef int ivol_i32;
typedef uint ivol_u32;
#else
#include <cstdint>
typedef std::int32_t ivol_i32;
typedef std::uint32_t ivol_u32;
#endif

/* How one view is weighted before the ramp filter (FDK's cosine weight, the
 * angular and Parker short-scan weights) and where its pixels lie. */
typedef struct FilterView {
  float scale;          /*  0: angular gap × 1/2 (full scan) or 1 (Parker) / ramp pitch */
  float sdd;            /*  4: source-to-detector distance, mm */
  float foot_u;         /*  8: detector u (mm) of the source's perpendicular foot */
  float foot_v;         /* 12: detector v (mm) of the source's perpendicular foot */
  float u_first;        /* 16: u (mm) of column 0's centre */
  float v_first;        /* 20: v (mm) of detector row 0's centre */
  float pitch_u;        /* 24: mm per column */
  float pitch_v;        /* 28: mm per row */
  float parker_beta;    /* 32: view angle from the start of a short scan, rad */
  float parker_delta;   /* 36: half the scan's excess over 180°, rad; < 0: full scan */
  float parker_sign;    /* 40: +1 or −1, the scan's sense of rotation */
  ivol_i32 reserved;    /* 44: zero */
} FilterView;           /* 48 bytes */

/* How one view backprojects: a 3×4 matrix from global voxel index (i, j, k, 1)
 * to (column·w, row·w, w), where w = (SID − depth)/SID so that the FDK
 * distance weight is 1/w². Column and row are detector indices of the whole
 * detector; the kernel subtracts the band's first row, an integer, so that a
 * voxel gets the same bits whatever slab it is reconstructed in. For a
 * circular scan column[2] = depth[2] = 0: a voxel column (i, j) keeps one
 * detector column and weight along k, which the kernel relies on. */
typedef struct BackprojectView {
  float column[4];      /*  0: row 0 of the matrix */
  float row[4];         /* 16: row 1 */
  float depth[4];       /* 32: row 2: w */
} BackprojectView;      /* 48 bytes */

/* Backprojection into the bricks of an inhomogeneous structure. A block
 * task holds IVOL_FINE_RUN lanes by IVOL_BACKPROJECT_DEPTH points along k:
 * lane x is the point (i + (x mod run_i)·step_i, j + (x div run_i)·step_j,
 * k + d·step_k) as grid indices, so that small bricks fill a block with
 * several rows. Full-resolution bricks use steps of 1 from integer indices,
 * so their voxels get exactly the bits the dense kernel gives them; coarse
 * bricks use the lattice of their voxels' octant centres. */
#define IVOL_FINE_RUN 16
typedef struct FineTask {
  float i;              /*  0 */
  float j;              /*  4 */
  float k;              /*  8 */
  float step_i;         /* 12 */
  float step_j;         /* 16 */
  float step_k;         /* 20 */
  ivol_u32 run_i;       /* 24: lanes per row along i, a power of two dividing IVOL_FINE_RUN */
  ivol_u32 count;       /* 28: points along i, j, k (bits 0-7, 8-15, 16-23); host bookkeeping */
} FineTask;             /* 32 bytes */

/* A coarse voxel on its own (an octree leaf), sampled at its centre or, when
 * it is wider than two voxels, at the centres of its eight octants (so that
 * it averages what it covers instead of aliasing): (i, j, k) is its centre as
 * a fractional grid index, quarter its edge / 4 along each axis. */
typedef struct CoarseTask {
  float i;              /*  0 */
  float j;              /*  4 */
  float k;              /*  8 */
  float quarter_i;      /* 12 */
  float quarter_j;      /* 16 */
  float quarter_k;      /* 20 */
  ivol_u32 reserved[2]; /* 24: zero */
} CoarseTask;           /* 32 bytes */

/* Filtered bands are stored with zero pixels around them so that bilinear
 * interpolation needs no bounds test: one zero column/row before the first
 * and BAND_BORDER_AFTER after the last. */
#define IVOL_BAND_BORDER_BEFORE 1
#define IVOL_BAND_BORDER_AFTER 2

/* Views backprojected per kernel launch, and voxels along k per work-item.
 * Slabs are allocated in whole stacks of IVOL_BACKPROJECT_DEPTH slices. */
#define IVOL_BACKPROJECT_BATCH 16
#define IVOL_BACKPROJECT_DEPTH 8

#endif
