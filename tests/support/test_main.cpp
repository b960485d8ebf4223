// The tests' main: GoogleTest's, after the check that makes a test binary
// started again as a library's child process (isolated_worker.hpp) serve its
// parent instead of running the tests.
#include <gtest/gtest.h>

namespace ivol::convert {
// Weak: a test that never starts a worker links without the converters.
[[gnu::weak]] void serve_if_worker_process();
}  // namespace ivol::convert

int main(int argc, char** argv) {
  if (ivol::convert::serve_if_worker_process) ivol::convert::serve_if_worker_process();
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
