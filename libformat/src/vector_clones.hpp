// Functions whose loops the compiler vectorises, built twice where the
// compiler can: for AVX2 and for the baseline, the loader choosing by the
// processor (GCC's target_clones, an ifunc). The library's baseline is
// x86-64 (SSE2); the predictor's rows, its moments and the stored levels'
// sums ran at two fifths of their AVX2 speed there. The results are the
// same either way: integer arithmetic, and sums in binary64 that are exact.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define IVOL_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define IVOL_VECTOR_CLONES
#endif
