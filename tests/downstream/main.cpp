// Writes and reads a tiny volume through the installed public headers.
#include <cstdio>
#include <ivol/build.hpp>
#include <ivol/check.hpp>
#include <ivol/reader.hpp>
#include <ivol/writer.hpp>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  const ivol::Dims dims{5, 4, 3};
  std::vector<float> volume(60);
  for (int i = 0; i < 60; ++i) volume[i] = static_cast<float>(i % 5);
  ivol::write_octree(ivol::build_octree(volume.data(), dims, {}).octree, ivol::Metadata{}, argv[1]);
  ivol::Reader reader(argv[1]);
  const bool ok = ivol::check_file(argv[1]).ok() && reader.voxel_value(3, 2, 1) == 3.0;
  std::puts(ok ? "downstream: ok" : "downstream: FAILED");
  return ok ? 0 : 1;
}
