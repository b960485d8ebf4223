// libFuzzer harness for the OpenVDB reader (tools/convert/vdb_io.cpp,
// read_vdb): the input is the .vdb file. Whatever it holds, read_vdb must
// return or throw (ivol::Error, or an exception from libopenvdb, which
// read_vdb turns into ivol::Error where it can): no crash, no sanitizer
// report, and no grid's dense box allocated beyond the budget given (well
// inside libFuzzer's -rss_limit_mb). Seeds: tests/fuzz/regressions/vdb/
// (a small grid, two grids, a tile, and grids at the edges of the 32-bit
// index space that crashed or hung the reader before, issue 17 item 3).
//   tests/fuzz/run_vdb.sh
#include <openvdb/openvdb.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>

#include "vdb_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/dev/shm/ivol-fuzz-vdb-" + std::to_string(getpid()) + ".vdb";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  if (size > 0) std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    (void)ivol::convert::read_vdb(path, "", std::uint64_t{256} << 20);
  } catch (const std::exception&) {
  }
  return 0;
}
