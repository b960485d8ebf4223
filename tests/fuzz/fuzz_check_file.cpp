// libFuzzer harness: check_file and the Reader's views on arbitrary bytes.
// Whatever the input, they must return or throw ivol::Error: no crash, no
// out-of-bounds access, no undefined behaviour, no unbounded allocation.
//
//   clang++ -fsanitize=fuzzer,address,undefined ... (see tests/fuzz/run.sh)
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/dev/shm/ivol-fuzz-" + std::to_string(getpid()) + ".ivol";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  (void)ivol::check_file(path);
  try {
    ivol::Reader reader(path);
    const ivol::Dims d = reader.layout().dims;
    if (ivol::voxel_count(d) <= (1u << 16)) {
      reader.read_lod(0);
      if (reader.layout().depth > 0) reader.read_lod(1);
    }
    reader.voxel_value(d[0] - 1, d[1] - 1, d[2] - 1);
    reader.read_slice(ivol::Axis::Z, d[2] / 2 < d[2] ? d[2] / 2 : 0);
  } catch (const ivol::Error&) {
  }
  return 0;
}
