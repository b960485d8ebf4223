// Writes the hostile .ivol files of tests/support/hostile_files.hpp:
//   make_hostile_files DIR [NAME...]   (all of them without names)
//   make_hostile_files --list          (name, whether refused, what it does)
// Used by tests/cli/run_hostile.sh; the small ones are also fuzzing seeds
// (tests/fuzz/regressions/hostile-*).
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "hostile_files.hpp"

int main(int argc, char** argv) {
  namespace hostile = ivol::test::hostile;
  if (argc < 2) {
    std::fprintf(stderr, "usage: make_hostile_files DIR [NAME...] | --list\n");
    return 1;
  }
  try {
    if (std::strcmp(argv[1], "--list") == 0) {
      for (const auto& f : hostile::catalogue())
        std::printf("%s %s %s\t%s\n", f.name.c_str(), f.refused ? "refused" : "readable", f.sparse ? "sparse" : "dense",
                    f.what.c_str());
      return 0;
    }
    const std::string dir = argv[1];
    if (argc == 2) {
      for (const auto& f : hostile::catalogue()) hostile::write(f.name, dir + "/" + f.name + ".ivol");
    } else {
      for (int a = 2; a < argc; ++a) hostile::write(argv[a], dir + "/" + std::string(argv[a]) + ".ivol");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_hostile_files: %s\n", e.what());
    return 1;
  }
  return 0;
}
