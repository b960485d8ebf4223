// The child process that third-party parsers run in (isolated_worker.hpp),
// and the HDF5 readers that use it: a library crash on a damaged file must
// become an ivol::Error naming the file, clean errors must come back
// unchanged, and the values must be those of the in-process readers.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "expect_error.hpp"
#include "hdf5_io.hpp"
#include "isolated_worker.hpp"
#include "ivol/error.hpp"
#include "projection_io.hpp"
#include "test_support.hpp"

namespace ivol::convert {
namespace {

using test::contains;
using test::error_of;

// The worker kinds these tests start: the child is this test binary started
// again (tests/support/test_main.cpp), so they are registered here.
const WorkerKind echo_worker("test-echo", [](std::string_view parameters) -> WorkerHandler {
  const std::string prefix(parameters);
  return [prefix](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const auto count = in.get<std::uint64_t>();
    out.reply = prefix + in.get_string();
    out.bulk.resize(count);
    for (std::size_t i = 0; i < count; ++i) out.bulk[i] = static_cast<char>(i * 7 + i / 4099);
  };
});

const WorkerKind failing_worker("test-errors", [](std::string_view) -> WorkerHandler {
  return [](std::string_view request, WorkerReply&) {
    if (request == "checksum") throw Error(ErrorClass::Checksum, "x.h5: chunk 3: checksum mismatch");
    throw std::runtime_error("x.h5: something else");
  };
});

const WorkerKind crashing_worker("test-crash", [](std::string_view) -> WorkerHandler {
  return [](std::string_view request, WorkerReply& out) {
    if (request == "kill") raise(SIGKILL);
    if (request == "segv") {
      volatile int* nowhere = nullptr;
      *nowhere = 1;  // under a sanitizer the child reports and exits instead
    }
    out.reply = "fine";
  };
});

// Tells what the child process is: its blocked signals and its descriptors.
const WorkerKind inspecting_worker("test-inspect", [](std::string_view) -> WorkerHandler {
  return [](std::string_view request, WorkerReply& out) {
    if (request == "blocked") {
      std::ifstream status("/proc/self/status");
      for (std::string line; std::getline(status, line);)
        if (line.rfind("SigBlk:", 0) == 0) out.reply = line.substr(7);
      return;
    }
    std::vector<std::string> descriptors;
    for (const auto& entry : std::filesystem::directory_iterator("/proc/self/fd"))
      descriptors.push_back(entry.path().filename().string());
    std::sort(descriptors.begin(), descriptors.end());
    for (const std::string& d : descriptors) out.reply += d + " ";
  };
});

TEST(IsolatedWorker, RepliesAndBulkDataArriveWhole) {
  IsolatedWorker worker("subject", "a library", "test-echo", "got ");
  for (std::uint64_t count : {std::uint64_t{0}, std::uint64_t{1}, std::uint64_t{48} << 20}) {
    WireWriter request;
    request.put(count).put_string("slab");
    std::vector<char> bulk(count, 0);
    EXPECT_EQ(worker.call(request.bytes(), "testing", bulk.data(), bulk.size()), "got slab");
    std::size_t wrong = 0;
    for (std::size_t i = 0; i < count; ++i) wrong += bulk[i] != static_cast<char>(i * 7 + i / 4099);
    EXPECT_EQ(wrong, 0u) << count << " bytes";
  }
}

TEST(IsolatedWorker, ChildErrorsComeBackWithTheirClassAndMessage) {
  IsolatedWorker worker("x.h5", "libhdf5", "test-errors", "");
  const Error checksum = error_of([&] { worker.call("checksum", "reading"); });
  EXPECT_EQ(checksum.error_class(), ErrorClass::Checksum);
  EXPECT_STREQ(checksum.what(), "x.h5: chunk 3: checksum mismatch");
  const Error other = error_of([&] { worker.call("other", "reading"); });
  EXPECT_EQ(other.error_class(), ErrorClass::Malformed);
  EXPECT_STREQ(other.what(), "x.h5: something else");
  // An error is not a crash: the child still serves.
  EXPECT_EQ(error_of([&] { worker.call("checksum", "reading"); }).error_class(), ErrorClass::Checksum);
}

TEST(IsolatedWorker, ACrashIsAnErrorNamingTheFileTheRequestAndTheSignal) {
  IsolatedWorker worker("scan.h5", "libhdf5", "test-crash", "");
  EXPECT_EQ(worker.call("ok", "warming up"), "fine");
  const Error killed = error_of([&] { worker.call("kill", "reading view 3 rows 0..8"); });
  EXPECT_EQ(killed.error_class(), ErrorClass::Malformed);
  EXPECT_TRUE(contains(killed.what(), "scan.h5: libhdf5 crashed (signal 9")) << killed.what();
  EXPECT_TRUE(contains(killed.what(), "while reading view 3 rows 0..8")) << killed.what();
  // The worker is gone: later calls are refused, not sent into a dead socket.
  const Error later = error_of([&] { worker.call("ok", "reading"); });
  EXPECT_TRUE(contains(later.what(), "stopped by an earlier failure")) << later.what();

  IsolatedWorker segv("scan.h5", "libhdf5", "test-crash", "");
  const Error crashed = error_of([&] { segv.call("segv", "opening"); });
  // Under a sanitizer, its handler reports and exits with a status instead.
  EXPECT_TRUE(contains(crashed.what(), "libhdf5 crashed (signal 11") ||
              contains(crashed.what(), "libhdf5 crashed (exit status"))
      << crashed.what();
}

TEST(IsolatedWorker, AnUnknownKindIsRefusedBeforeAnyProcessStarts) {
  const Error e = error_of([] { IsolatedWorker("x.h5", "libhdf5", "no-such-kind", ""); });
  EXPECT_TRUE(contains(e.what(), "no worker kind \"no-such-kind\"")) << e.what();
}

TEST(IsolatedWorker, TheChildEndsWithTheWorker) {
  // A child that lived on would keep the parent's descriptors, and the lock
  // on its temporary file, alive.
  pid_t child = -1;
  {
    IsolatedWorker worker("subject", "a library", "test-crash", "");
    child = worker.child();
    EXPECT_EQ(worker.call("", "checking"), "fine");
    EXPECT_EQ(::kill(child, 0), 0);
  }
  EXPECT_NE(::kill(child, 0), 0) << "the child outlived its worker";
  EXPECT_EQ(errno, ESRCH);
}

// The child is a fresh process, not a copy of the parent: none of the
// parent's descriptors (an output file, MPI's sockets) and none of its
// blocked signals (ivol's MPI signal thread blocks them in every other
// thread) reach it.
TEST(IsolatedWorker, TheChildIsAFreshProcessWithOnlyItsSocket) {
  const std::string kept = ivol::test::temp_path("kept-open");
  const int fd = ::open(kept.c_str(), O_CREAT | O_WRONLY, 0600);  // no O_CLOEXEC
  ASSERT_GE(fd, 0);
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_BLOCK, &all, &before);
  IsolatedWorker worker("subject", "a library", "test-inspect", "");
  pthread_sigmask(SIG_SETMASK, &before, nullptr);
  ::close(fd);
  // 0-2, the socket (3) and the listing's own descriptor.
  const std::string descriptors = worker.call("descriptors", "listing");
  EXPECT_EQ(descriptors, "0 1 2 3 4 ") << descriptors;
  EXPECT_EQ(worker.call("blocked", "reading the signal mask"), "\t0000000000000000");
}

// Starting a worker while other threads allocate: a fork without exec could
// copy an allocator lock held by one of them and hang in the child's first
// malloc (seen with MPI's and PoCL's threads under AddressSanitizer).
TEST(IsolatedWorker, StartsWhileOtherThreadsAllocate) {
  std::atomic<bool> stop{false};
  std::vector<std::thread> busy;
  for (int t = 0; t < 3; ++t)
    busy.emplace_back([&stop] {
      while (!stop.load(std::memory_order_relaxed)) {
        std::vector<std::unique_ptr<std::string>> held;
        for (int i = 0; i < 64; ++i)
          held.push_back(std::make_unique<std::string>(static_cast<std::size_t>(i * 37), 'x'));
      }
    });
  for (int round = 0; round < 20; ++round) {
    IsolatedWorker worker("subject", "a library", "test-echo", "round ");
    WireWriter request;
    request.put(std::uint64_t{1} << 16).put_string(std::to_string(round));
    std::vector<char> bulk(std::size_t{1} << 16);
    EXPECT_EQ(worker.call(request.bytes(), "testing", bulk.data(), bulk.size()), "round " + std::to_string(round));
  }
  stop = true;
  for (std::thread& t : busy) t.join();
}

// --- The HDF5 readers through the worker -------------------------------------

std::string source_dir() { return IVOL_SOURCE_DIR; }

// A kept fuzzing input (first byte: the harness's format selector) as a file.
std::string regression_file(const std::string& name) {
  std::ifstream in(source_dir() + "/tests/fuzz/regressions/" + name, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_GT(bytes.size(), 1u) << name;
  const std::string path = ivol::test::temp_path(std::filesystem::path(name).filename().string() + ".h5");
  std::ofstream(path, std::ios::binary) << bytes.substr(1);
  return path;
}

// Debian 12's libhdf5 1.10.8 crashes on this file in any build
// (tests/fuzz/regressions/README.md); other versions may refuse it cleanly.
constexpr bool kLibraryCrashesOnNullRead = H5_VERS_MAJOR == 1 && H5_VERS_MINOR == 10 && H5_VERS_RELEASE == 8;

TEST(Hdf5Isolation, ALibraryCrashOnADamagedVolumeIsAnErrorNamingTheFile) {
  const std::string path = regression_file("libhdf5/converters-hdf5-null-read");
  const Error e = error_of([&] { read_hdf5(path); });
  EXPECT_EQ(e.error_class(), ErrorClass::Malformed);
  EXPECT_TRUE(contains(e.what(), path)) << e.what();
  if (kLibraryCrashesOnNullRead)
    EXPECT_TRUE(contains(e.what(), "libhdf5 crashed") && contains(e.what(), "opening dataset /exchange/data"))
        << e.what();
}

TEST(Hdf5Isolation, ALibraryCrashOnDamagedProjectionsIsAnErrorNamingTheFile) {
  const std::string path = regression_file("libhdf5/converters-hdf5-null-read");
  const Error e = error_of([&] { open_dxchange_projections(path, {true, 1e-3}); });
  EXPECT_TRUE(contains(e.what(), path)) << e.what();
  if (kLibraryCrashesOnNullRead) EXPECT_TRUE(contains(e.what(), "libhdf5 crashed")) << e.what();
}

// Line integrals made up on the spot, for write_dxchange.
class MadeUpScan final : public ivol::recon::ProjectionSource {
 public:
  int columns() const override { return 7; }
  int rows() const override { return 5; }
  std::size_t view_count() const override { return 4; }
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override {
    for (int r = row_begin; r < row_end; ++r)
      for (int c = 0; c < columns(); ++c) *out++ = static_cast<float>(0.01 * c + 0.1 * r + 0.37 * view);
  }
};

TEST(Hdf5Isolation, ProjectionsThroughTheChildEqualThoseReadInProcess) {
  MadeUpScan scan;
  FieldImages fields;
  fields.flat.assign(35, 1000.0f);
  fields.dark.assign(35, 10.0f);
  fields.dark[3] = 1200.0f;  // a dead pixel: F − D below the floor, clamped at every read
  const std::string path = ivol::test::temp_path("isolated_dx.h5");
  write_dxchange(path, scan, {0.0, 45.0, 90.0, 135.0}, fields);

  DxchangeProjections here = open_dxchange_projections_in_process(path);
  DxchangeProjections there = open_dxchange_projections(path);
  EXPECT_EQ(there.theta_deg, here.theta_deg);
  EXPECT_EQ(there.projections->quantity(), StoredQuantity::Intensities);
  EXPECT_EQ(there.projections->columns(), 7);
  EXPECT_EQ(there.projections->rows(), 5);
  EXPECT_EQ(there.projections->view_count(), 4u);
  std::vector<float> a(35), b(35);
  for (std::size_t v = 0; v < 4; ++v) {
    here.projections->read_rows(v, 0, 5, a.data());
    there.projections->read_rows(v, 0, 5, b.data());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << "view " << v;
    here.projections->read_rows(v, 2, 4, a.data());
    there.projections->read_rows(v, 2, 4, b.data());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), 14 * sizeof(float)), 0) << "view " << v << " rows 2..4";
  }
  EXPECT_EQ(there.projections->clamped_pixels(), 4u);
  EXPECT_EQ(there.projections->clamped_pixels(), here.projections->clamped_pixels());
  // The child checks arguments as the reader in this process does.
  EXPECT_EQ(error_of([&] { there.projections->read_rows(4, 0, 1, b.data()); }).error_class(),
            ErrorClass::InvalidArgument);
}

// Files on which libhdf5 reads out of bounds: harmless or refused in a normal
// build, a sanitizer's exit in the child under ASan. Either way this process
// goes on, and every failure names the file.
TEST(Hdf5Isolation, OverreadsInTheLibraryNeverReachThisProcess) {
  const std::string volume = regression_file("converters-hdf5-chunk-overread");
  try {
    const DenseVolume v = read_hdf5(volume);
    EXPECT_EQ(v.dims, (Dims{5, 4, 3}));
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), volume)) << e.what();
  }
  const std::string scan = regression_file("libhdf5/converters-dxchange-chunk-overread");
  try {
    DxchangeProjections p = open_dxchange_projections(scan, {true, 1e-3});
    std::vector<float> rows(static_cast<std::size_t>(p.projections->columns()) * p.projections->rows());
    for (std::size_t v = 0; v < p.projections->view_count(); ++v)
      p.projections->read_rows(v, 0, p.projections->rows(), rows.data());
    ADD_FAILURE() << "a damaged chunk was read without an error";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), scan)) << e.what();
  }
}

}  // namespace
}  // namespace ivol::convert
