// Which vector instructions the library's hand-written paths use, and the
// functions the compiler builds twice.
#pragma once

namespace ivol::detail {

// Whether the processor has AVX2 and the environment does not turn it off
// (IVOL_DISABLE_AVX2 set to anything: the tests run the scalar paths so on
// machines that have it). Read once.
bool use_avx2();

}  // namespace ivol::detail

// Functions whose loops the compiler vectorises, built twice where the
// compiler can: for AVX2 and for the baseline, the loader choosing by the
// processor (GCC's target_clones, an ifunc; IVOL_DISABLE_AVX2 does not
// reach it). The library's baseline is x86-64 (SSE2): the predictor's
// rows and its moments ran at about half their AVX2 speed there. The
// results are the same either way: integer arithmetic, and sums in
// binary64 that are exact.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define IVOL_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define IVOL_VECTOR_CLONES
#endif
