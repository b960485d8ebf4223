#include "cpu_features.hpp"

#include <cstdlib>

namespace ivol::detail {

bool use_avx2() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  static const bool use = __builtin_cpu_supports("avx2") && std::getenv("IVOL_DISABLE_AVX2") == nullptr;
  return use;
#else
  return false;
#endif
}

}  // namespace ivol::detail
