#include "cube_writers.hpp"

#include "cpu_features.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#include <immintrin.h>
#define IVOL_HAVE_CUBE_WRITERS 1
#endif

namespace ivol::detail {

#ifdef IVOL_HAVE_CUBE_WRITERS
namespace {

// Children 2p and 2p+1 (dx = 0 and 1) as eight floats each, a and b: their
// rows are (a0 a1 b0 b1), (a2 a3 b2 b3) one y on, (a4 a5 b4 b5) one z on,
// (a6 a7 b6 b7) both.
__attribute__((target("avx2"))) inline void put_pair(__m256 a, __m256 b, float* p, std::uint64_t nx,
                                                     std::uint64_t plane) {
  const __m256d lo = _mm256_unpacklo_pd(_mm256_castps_pd(a), _mm256_castps_pd(b));
  const __m256d hi = _mm256_unpackhi_pd(_mm256_castps_pd(a), _mm256_castps_pd(b));
  _mm_storeu_ps(p, _mm_castpd_ps(_mm256_castpd256_pd128(lo)));
  _mm_storeu_ps(p + nx, _mm_castpd_ps(_mm256_castpd256_pd128(hi)));
  _mm_storeu_ps(p + plane, _mm_castpd_ps(_mm256_extractf128_pd(lo, 1)));
  _mm_storeu_ps(p + plane + nx, _mm_castpd_ps(_mm256_extractf128_pd(hi, 1)));
}

// Child c lies 2 voxels on along x if c & 1, along y if c & 2, along z if c & 4.
__attribute__((target("avx2,f16c"))) void binary16_cube(const std::uint8_t* values, float* out, std::uint64_t nx,
                                                        std::uint64_t plane) {
  for (unsigned pair = 0; pair < 4; ++pair) {
    const std::uint8_t* v = values + 32 * pair;
    const __m256 a = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(v)));
    const __m256 b = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(v + 16)));
    put_pair(a, b, out + (pair & 1u) * 2 * nx + (pair >> 1) * 2 * plane, nx, plane);
  }
}

__attribute__((target("avx2"))) void uint16_cube(const std::uint8_t* values, float* out, std::uint64_t nx,
                                                 std::uint64_t plane) {
  for (unsigned pair = 0; pair < 4; ++pair) {
    const std::uint8_t* v = values + 32 * pair;
    const __m256 a = _mm256_cvtepi32_ps(_mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(v))));
    const __m256 b =
        _mm256_cvtepi32_ps(_mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(v + 16))));
    put_pair(a, b, out + (pair & 1u) * 2 * nx + (pair >> 1) * 2 * plane, nx, plane);
  }
}

}  // namespace

// Read from CPUID leaf 1 (ECX bit 29): clang 14, which builds the fuzz
// harnesses, knows no "f16c" for __builtin_cpu_supports.
static bool cpu_has_f16c() {
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  return __get_cpuid(1, &eax, &ebx, &ecx, &edx) != 0 && (ecx & bit_F16C) != 0;
}

CubeWriter binary16_cube_writer() {
  static const bool has = use_avx2() && cpu_has_f16c();
  return has ? binary16_cube : nullptr;
}

CubeWriter uint16_cube_writer() {
  static const bool has = use_avx2();
  return has ? uint16_cube : nullptr;
}
#else
CubeWriter binary16_cube_writer() { return nullptr; }
CubeWriter uint16_cube_writer() { return nullptr; }
#endif

}  // namespace ivol::detail
