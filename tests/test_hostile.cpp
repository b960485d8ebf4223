// Hostile files (issue 17): crafted with valid CRCs, each must be refused or
// read without a crash, a hang or memory out of proportion to the request.
// Memory is measured in a child process (its peak resident size from
// wait4), so that one case's peak does not hide another's.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <set>
#include <string>

#include "hostile_files.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;
namespace hostile = ivol::test::hostile;

constexpr long kMiB = 1024;  // ru_maxrss is in KiB
// AddressSanitizer keeps up to 256 MiB of freed memory in quarantine (its
// default quarantine_size_mb) and shadows what is live: the bounds below are
// what the reader holds, plus that in the sanitizer build.
#if defined(__SANITIZE_ADDRESS__)
constexpr long kSanitizerSlack = 320 * kMiB;
#else
constexpr long kSanitizerSlack = 0;
#endif

struct ChildRun {
  bool ok = false;       // the function returned without a failed expectation
  long peak_kib = 0;     // peak resident set of the child
  double seconds = 0.0;  // wall time
};

// Runs `body` in a child process; `body` returns true when its own checks
// passed. An exception or a crash counts as failure.
ChildRun in_child(const std::function<bool()>& body) {
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    bool ok = false;
    try {
      ok = body();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "child: %s\n", e.what());
    }
    _exit(ok ? 0 : 1);
  }
  int status = 0;
  rusage usage{};
  wait4(pid, &status, 0, &usage);
  ChildRun run;
  run.ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  run.peak_kib = usage.ru_maxrss;
  run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("  child: peak %ld MiB, %.1f s\n", run.peak_kib / kMiB, run.seconds);
  return run;
}

std::string make(const std::string& name) {
  const std::string path = test::temp_path(name + ".ivol");
  hostile::write(name, path);
  return path;
}

// The first problem check_file reports, or "" when it finds none.
std::pair<ErrorClass, std::string> first_problem(const std::string& path) {
  const CheckReport report = check_file(path);
  if (report.ok()) return {ErrorClass::Io, ""};
  return {report.problems[0].error_class, report.problems[0].message};
}

void expect_refused_on_open(const std::string& path, ErrorClass expected, const std::string& words) {
  try {
    Reader reader(path);
    ADD_FAILURE() << path << " was opened";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), expected) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(Hostile, DeeplyNestedMetadataIsRefusedBeforeParsing) {
  for (const char* name : {"deep_json_objects", "deep_json_arrays"}) {
    const std::string path = make(name);
    // A stack overflow kills the child: the run then fails instead of the
    // whole test program.
    const ChildRun run = in_child([&] {
      expect_refused_on_open(path, ErrorClass::Malformed, "nested deeper than 128");
      const auto problem = first_problem(path);
      return problem.first == ErrorClass::Malformed && problem.second.find("deeper than 128") != std::string::npos &&
             !::testing::Test::HasFailure();
    });
    EXPECT_TRUE(run.ok) << name;
  }
}

TEST(Hostile, MetadataNestingLimitIsExactly128) {
  const std::string at_limit = test::temp_path("depth128.ivol");
  const std::string beyond = test::temp_path("depth129.ivol");
  hostile::write_one_voxel(hostile::deep_metadata(126, true), at_limit);
  hostile::write_one_voxel(hostile::deep_metadata(127, false), beyond);
  EXPECT_TRUE(check_file(at_limit).ok()) << first_problem(at_limit).second;
  EXPECT_EQ(Reader(at_limit).metadata().user.size(), 1u);
  expect_refused_on_open(beyond, ErrorClass::Malformed, "nested deeper than 128");
  EXPECT_EQ(json_nesting_depth(hostile::deep_metadata(126, true), 1000), 128u);
  EXPECT_EQ(json_nesting_depth(hostile::deep_metadata(127, false), 1000), 129u);
  // Brackets inside strings do not nest.
  EXPECT_EQ(json_nesting_depth(R"({"a":"[[[{\"{{","b":[{}]})", 1000), 3u);
}

TEST(Hostile, DagOctreeIsRefusedByPartialAndWholeReads) {
  const std::string path = make("dag_octree");
  Reader reader(path);
  auto expect_numbering_error = [&](const std::function<void()>& read, const std::string& what) {
    try {
      read();
      ADD_FAILURE() << what << " read the DAG";
    } catch (const Error& e) {
      EXPECT_EQ(e.error_class(), ErrorClass::Malformed) << e.what();
      EXPECT_NE(std::string(e.what()).find("breadth-first order requires"), std::string::npos) << e.what();
    }
  };
  expect_numbering_error([&] { reader.read_slice(Axis::X, 0); }, "an x-slice");
  expect_numbering_error([&] { reader.read_box(Box{{0, 0, 0}, {1024, 1024, 4}}); }, "a slab (as export reads)");
  expect_numbering_error([&] { reader.read_lod(8); }, "level of detail 8 (whole level)");
  EXPECT_FALSE(check_file(path).ok());
}

TEST(Hostile, ZstdStoredSizeIsBoundedBeforeReading) {
  const std::string path = make("zstd_block_4gib");
  const ChildRun run = in_child([&] {
    expect_refused_on_open(path, ErrorClass::Malformed, "the largest zstd frame of its 4 decoded bytes");
    return first_problem(path).first == ErrorClass::Malformed && !::testing::Test::HasFailure();
  });
  EXPECT_TRUE(run.ok);
  EXPECT_LT(run.peak_kib, 200 * kMiB + kSanitizerSlack);
}

TEST(Hostile, ClaimedIndexSizeIsBoundedBeforeReading) {
  const std::string path = make("index_6gib");
  const ChildRun run = in_child([&] {
    expect_refused_on_open(path, ErrorClass::Malformed, "footer: index_size 6442450944 exceeds what");
    return !::testing::Test::HasFailure();
  });
  EXPECT_TRUE(run.ok);
  EXPECT_LT(run.peak_kib, 200 * kMiB + kSanitizerSlack);
}

TEST(Hostile, UnknownStreamBlockCrcIsCheckedInParts) {
  const std::string path = make("unknown_stream_2gib");
  const ChildRun run = in_child([&] {
    Reader reader(path);  // ignorable: the reader skips it
    const bool value_ok = reader.voxel_value(0, 0, 0) == 1.0;
    const auto problem = first_problem(path);
    return value_ok && problem.first == ErrorClass::Checksum &&
           problem.second.find("block 2 (unknown stream") != std::string::npos;
  });
  EXPECT_TRUE(run.ok);
  EXPECT_LT(run.peak_kib, 200 * kMiB + kSanitizerSlack);
}

TEST(Hostile, LevelOfDetailOfALargeGridHoldsTheOutputNotTheRegion) {
  const std::string path = make("regular_grid_2gib");
  const ChildRun run = in_child([&] {
    Reader reader(path);
    // One layer of level of detail 8 (4x4x2): 256 full-resolution slices.
    const std::vector<float> lod = reader.read_box(Box{{0, 0, 1}, {4, 4, 2}}, 8);
    return lod == std::vector<float>(16, 0.0f);
  });
  EXPECT_TRUE(run.ok);
  // The cache's 256 MiB and the 64 MiB block in use; the region under the
  // 16 voxels asked for is 1 GiB.
  EXPECT_LT(run.peak_kib, 450 * kMiB + kSanitizerSlack);
}

TEST(Hostile, CacheBudgetIsInBytes) {
  const std::string path = make("regular_grid_2gib");
  for (const std::uint64_t budget : {std::uint64_t{0}, std::uint64_t{256} << 20}) {
    const ChildRun run = in_child([&] {
      ReaderOptions options;
      options.cache_bytes = budget;
      Reader reader(path, options);
      // An x-slice needs one voxel of every row: all 32 blocks, in order.
      const std::vector<float> slice = reader.read_slice(Axis::X, 1023);
      return slice.size() == 1024u * 512u && reader.io_stats().blocks_decoded == 33;  // and the metadata
    });
    EXPECT_TRUE(run.ok) << budget;
    // The budget plus the block in use (64 MiB); 32 blocks of 64 MiB are 2 GiB.
    EXPECT_LT(run.peak_kib, static_cast<long>(budget >> 10) + 200 * kMiB + kSanitizerSlack) << budget;
  }
}

TEST(Hostile, HugeRectilinearGridOpensWithoutAPerVoxelTable) {
  const std::string path = make("rectilinear_2p29");
  const ChildRun run = in_child([&] {
    Reader reader(path);
    const std::uint32_t last = (1u << 29) - 1;
    // The whole volume is 2^87 voxels: Box::voxel_count wraps to 0, and the
    // read must say so rather than fill an empty output.
    bool refused = false;
    try {
      reader.read_lod(0);
    } catch (const Error& e) {
      refused = e.error_class() == ErrorClass::InvalidArgument;
    }
    // One voxel of level of detail 20 sums 2^60 voxels (spec §12.3): over
    // the reader's limit, refused at once instead of running for years.
    bool limited = false;
    try {
      reader.read_box(Box{{0, 0, 0}, {1, 1, 1}}, 20);
    } catch (const Error& e) {
      limited = e.error_class() == ErrorClass::LimitExceeded;
    }
    return refused && limited && reader.voxel_value(last, last, last) == 2.5 && reader.voxel_value(0, last, 7) == 2.5 &&
           reader.read_box(Box{{last - 1, 0, 5}, {last + 1, 2, 6}}) == std::vector<float>(4, 2.5f);
  });
  EXPECT_TRUE(run.ok);
  EXPECT_LT(run.peak_kib, 100 * kMiB + kSanitizerSlack);  // a table per voxel: 6 GiB
  EXPECT_LT(run.seconds, 10.0);
}

TEST(Hostile, SalvageListsOneEntryPerDamagedBlock) {
  const std::string path = make("salvage_zeroed");
  Reader reader(path);
  std::vector<DamagedRegion> damaged;
  const Dims d = reader.layout().dims;
  // As export reads: slabs of whole slices, one list.
  for (std::uint32_t z = 0; z < d[2]; z += 40) {
    Box slab = full_box(d);
    slab.lo[2] = z;
    slab.hi[2] = std::min(d[2], z + 40);
    reader.read_box(slab, 0, &damaged);
  }
  const CheckReport report = check_file(path);
  ASSERT_GT(report.blocks_damaged, 10u);
  EXPECT_GT(damaged.size(), 0u);
  // Entries merged per cause (a damaged block, or a broken node) into the
  // few exact boxes its regions form, at most 1001 in all: not one per
  // voxel, of which there are 1.6 million in the damaged blocks.
  EXPECT_LE(damaged.size(), std::min<std::size_t>(4 * report.blocks_damaged, 1001));
  std::set<std::string> causes;
  for (const DamagedRegion& r : damaged) causes.insert(r.message);
  EXPECT_LE(causes.size(), report.blocks_damaged);
}

}  // namespace

namespace {

// A valid file of 2^31 voxels a side has 2^93 voxels: the counts wrapped to
// 0 at 64 bits (info printed "dense float32 0 B"; a read of the whole box
// got a buffer of 0 floats to fill). They are now refused by name, and
// reads larger than memory are LimitExceeded, not std::bad_alloc.
TEST(Hostile, VoxelCountsPast64BitsAreRefusedNotWrapped) {
  const Dims side31{1u << 31, 1u << 31, 1u << 31};
  std::string message;
  try {
    (void)voxel_count(side31);
    ADD_FAILURE() << "2^93 voxels were counted";
  } catch (const Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::LimitExceeded);
    message = e.what();
  }
  EXPECT_NE(message.find("2147483648x2147483648x2147483648"), std::string::npos) << message;
  EXPECT_THROW((void)full_box(side31).voxel_count(), Error);
  // 2^64 - 2^33 + 1 voxels still count exactly; 2^64 do not.
  EXPECT_EQ(voxel_count(Dims{0xFFFFFFFFu, 0xFFFFFFFFu, 1}), 0xFFFFFFFE00000001ull);
  EXPECT_THROW((void)voxel_count(Dims{1u << 31, 1u << 31, 4}), Error);
  EXPECT_EQ(voxel_count_approx(side31), 0x1p93);
}

TEST(Hostile, ReadsOfTheOneLeafFileOf2To31ASideAreLimitsNotCrashes) {
  const std::string path = std::string(IVOL_SOURCE_DIR) + "/tests/fuzz/regressions/ivol/one-leaf-2e31.ivol";
  Reader reader(path);
  ASSERT_EQ(reader.layout().dims, (Dims{1u << 31, 1u << 31, 1u << 31}));
  // The whole box is refused as a request (more than 2^62 voxels); one
  // slice of 2^62 voxels is asked for properly and cannot be allocated:
  // std::length_error before, now a limit naming the box.
  EXPECT_THROW((void)reader.read_box(full_box(reader.layout().dims), 0), Error);
  for (const Box& box : {slice_box(reader.layout().dims, Axis::Z, 0), slice_box(reader.layout().dims, Axis::X, 7)}) {
    std::string message;
    try {
      (void)reader.read_box(box, 0);
      ADD_FAILURE() << "read " << box.to_string();
    } catch (const Error& e) {
      EXPECT_EQ(e.error_class(), ErrorClass::LimitExceeded) << e.what();
      message = e.what();
    }
    EXPECT_NE(message.find(box.to_string()), std::string::npos) << message;
  }
  // A small box of it reads, with the leaf's value.
  Box small;
  small.lo = {(1u << 31) - 2, 5, 7};
  small.hi = {1u << 31, 7, 9};
  const std::vector<float> values = reader.read_box(small, 0);
  ASSERT_EQ(values.size(), 8u);
  for (float v : values) EXPECT_EQ(v, reader.voxel_value(0, 0, 0));
}

}  // namespace
