// The ramp filter's FFTs in native code for CPU devices, beside the OpenCL
// kernel fdk_filter_rows (kernels/fdk_filter.cl), which stays the GPU path.
//
// Under PoCL the kernel's radix-2 Stockham FFT runs a work-group of up to
// 256 work-items through a barrier per stage, for one pair of detector rows
// (one row the real part, the next the imaginary). Here each lane of a
// vector holds its own pair: sixteen pairs go through the same butterflies
// with the twiddle broadcast, no shuffles. The kernel fdk_weight_rows
// weights the rows first, on the device, so that the weights keep the
// device's atan, sin and rsqrt; from there on every operation is the
// kernel's, with the fused multiply-adds where its compiler contracts, and
// the filtered rows get its bits (test_fdk_native).
#pragma once

#include <cstddef>

namespace ivol::recon::detail {

bool native_filter_available();

struct NativeFilterBatch {
  const float* weighted;  // view_count images of band_rows × columns, fdk_weight_rows' output
  int columns = 0;
  int band_rows = 0;
  int view_count = 0;
  int log2n = 0;
  const float* twiddles = nullptr;  // n/2 complex values, interleaved (FdkProblem::twiddles)
  const float* response = nullptr;  // n real values (FdkProblem::response)
  float* filtered = nullptr;        // per view stride_rows × stride_cols, inside the zero border
  int stride_cols = 0;
  int stride_rows = 0;
};

// Filters the batch as fdk_filter_rows does after its weighting, on
// `threads` threads; leaves the border (and rows of views not in the batch)
// as they were.
void filter_rows_native(const NativeFilterBatch& batch, unsigned threads);

}  // namespace ivol::recon::detail
