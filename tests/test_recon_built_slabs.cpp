// A distributed dense reconstruction (recon_io/recon_built_slabs.hpp), and
// one into an octree structure (recon_io/recon_built_structure.hpp), with
// their ranks as threads of one process, over an in-memory exchange: every
// rank builds the subtrees of its own writer slabs, rank 0 writes them, and
// the file is the one a single process writes; a rank that fails while
// building makes rank 0 fail with its message and leave nothing.
// (tests/cli/run_mpi.sh runs the same under mpirun.)
#include <gtest/gtest.h>

#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol_io.hpp"
#include "recon_built_layers.hpp"
#include "recon_built_slabs.hpp"
#include "recon_built_structure.hpp"
#include "recon_slabs.hpp"
#include "test_support.hpp"

namespace ivol {
namespace {

// The mailbox every rank's exchange shares: slabs to rank 0, and failures.
struct Mailbox {
  std::mutex mutex;
  std::condition_variable changed;
  std::map<std::size_t, std::vector<std::uint8_t>> slabs;
  std::optional<std::pair<int, std::string>> failure;
  std::uint64_t bytes_to_rank0 = 0;
};

class ThreadExchange final : public recon::SlabExchange {
 public:
  ThreadExchange(Mailbox& mailbox, int rank, int size) : mailbox_(mailbox), rank_(rank), size_(size) {}
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  // Every rank computes the same values here; the MPI exchange checks it.
  std::uint64_t agree(std::uint64_t value, const std::string&) override { return value; }
  void broadcast(std::vector<float>&) override { throw std::logic_error("no preview in these tests"); }
  void send(std::size_t, const std::vector<float>&) override { throw std::logic_error("dense slabs go as bytes"); }
  void receive(std::size_t, int, std::vector<float>&) override { throw std::logic_error("dense slabs go as bytes"); }
  void send_bytes(std::size_t slab, const std::vector<std::uint8_t>& data) override {
    std::lock_guard<std::mutex> lock(mailbox_.mutex);
    mailbox_.slabs[slab] = data;
    mailbox_.bytes_to_rank0 += data.size();
    mailbox_.changed.notify_all();
  }
  void receive_bytes(std::size_t slab, int, std::vector<std::uint8_t>& data) override {
    std::unique_lock<std::mutex> lock(mailbox_.mutex);
    mailbox_.changed.wait(lock, [&] { return mailbox_.slabs.count(slab) > 0 || mailbox_.failure.has_value(); });
    if (mailbox_.failure)
      throw std::runtime_error("rank " + std::to_string(mailbox_.failure->first) + ": " + mailbox_.failure->second);
    data = std::move(mailbox_.slabs[slab]);
    mailbox_.slabs.erase(slab);
  }
  void report_failure(const std::string& message) override {
    std::lock_guard<std::mutex> lock(mailbox_.mutex);
    if (!mailbox_.failure) mailbox_.failure = std::make_pair(rank_, message);
    mailbox_.changed.notify_all();
  }

 private:
  Mailbox& mailbox_;
  int rank_;
  int size_;
};

struct Scan {
  recon::ScanGeometry geometry = recon::circular_scan({96, 80, 1.2, 1.2}, 90, 300.0, 600.0, 2 * M_PI, 0.1, 1.5, -2.0);
  recon::VolumeGrid grid = recon::VolumeGrid::centred({40, 36, 33}, 1.0);
  recon::InMemoryProjections projections = recon::project_scan(recon::pencil_holder(18.0), geometry);
};

struct RankOutcome {
  convert::DistributedBuild built;
  std::string error;  // what it threw, if it did
};

// `ranks` threads, each with its own reconstructor, as mpirun's processes.
// The reconstructors are made one after the other: setting up OpenCL from
// several threads at once is not safe (PoCL crashes), and processes never do.
template <typename Outcome, typename Rank>
std::vector<Outcome> run_threads(Scan& scan, int ranks, Mailbox& mailbox, Rank&& rank) {
  std::vector<Outcome> outcomes(static_cast<std::size_t>(ranks));
  std::vector<std::unique_ptr<recon::FdkReconstructor>> reconstructors;
  for (int r = 0; r < ranks; ++r)
    reconstructors.push_back(std::make_unique<recon::FdkReconstructor>(scan.projections, scan.geometry));
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r) {
    threads.emplace_back([&, r] {
      Outcome& mine = outcomes[static_cast<std::size_t>(r)];
      try {
        ThreadExchange exchange(mailbox, r, ranks);
        mine.built = rank(*reconstructors[static_cast<std::size_t>(r)], exchange);
      } catch (const std::exception& e) {
        mine.error = e.what();
      }
    });
  }
  for (auto& t : threads) t.join();
  return outcomes;
}

std::vector<RankOutcome> run_ranks(Scan& scan, int ranks, const std::string& path,
                                   const convert::ImportOptions& options, std::uint32_t most_slab_slices,
                                   Mailbox& mailbox) {
  return run_threads<RankOutcome>(scan, ranks, mailbox, [&](recon::FdkReconstructor& r, ThreadExchange& exchange) {
    return convert::reconstruct_distributed(r, scan.grid, path, options, exchange, most_slab_slices, [] {});
  });
}

struct StructureRankOutcome {
  convert::DistributedStructureBuild built;
  std::string error;
};

// An octree with full resolution in two cubes of 8³ and coarse leaves up to
// 32 voxels across elsewhere: leaves far taller than the writer's slabs.
std::unique_ptr<VoxelStructure> two_cube_octree(const Dims& dims) {
  NeedMask mask;
  mask.dims = dims;
  mask.factor = 8;
  mask.cells = {5, 5, 5};
  mask.need.assign(125, 0);
  mask.need[(2 * 5 + 2) * 5 + 1] = mask.need[(1 * 5 + 3) * 5 + 2] = 1;
  return generate_structure(StructureKind::Octree, mask);
}

std::vector<StructureRankOutcome> run_structure_ranks(Scan& scan, int ranks, const VoxelStructure& structure,
                                                      const std::string& path, Mailbox& mailbox) {
  convert::DistributedStructureOptions options;
  options.most_slab_slices = 4;
  return run_threads<StructureRankOutcome>(
      scan, ranks, mailbox, [&](recon::FdkReconstructor& r, ThreadExchange& exchange) {
        return convert::reconstruct_structure_distributed(r, scan.grid, structure, path, options, exchange);
      });
}

TEST(ReconBuiltSlabs, SameFileAsOneProcess) {
  Scan scan;
  enum Kind { kOctree, kKeep, kBricked, kBrickedLayers, kBrickedFloat32 };
  for (const Kind kind : {kOctree, kKeep, kBricked, kBrickedLayers, kBrickedFloat32}) {
    const bool keep = kind == kKeep;
    convert::ImportOptions options;
    // float32: every bit of the FDK's values, in bricks of byte planes.
    options.encoding = kind == kBrickedFloat32 ? ValueEncoding::Float32 : ValueEncoding::Binary16;
    // Octree: the ranks build its subtrees; with a keep mask, ivol recon's
    // choice. Bricked: ivol recon's dense default, the ranks' slabs its
    // stored values; layers of 16 (16, 16 and 1 slices) in slabs of 4, or
    // layers of 8 in slabs of two whole layers (16, 16 and 1 slices).
    options.structure = kind == kOctree ? convert::StructureChoice::Octree : convert::StructureChoice::Auto;
    if (kind == kBricked || kind == kBrickedFloat32) options.brick_log2 = 4;
    if (kind == kBrickedLayers) options.brick_log2 = 3;
    const std::uint32_t slab = kind == kBrickedLayers ? 16 : 4;
    if (keep) options.keep = convert::KeepRule{false, 0.01F, 2};
    const std::string one_path = test::temp_path("recon-one.ivol");
    {
      recon::FdkReconstructor reconstructor(scan.projections, scan.geometry);
      convert::ReconstructionSlabs slabs(reconstructor, scan.grid, keep ? options.keep->margin : 0);
      convert::import_to_ivol(slabs, one_path, options);  // the writer's own slabs: one, of 64 slices
    }
    // Writer slabs of 4 slices (9 of them, 3 per rank), each with its margin.
    Mailbox mailbox;
    const std::string path = test::temp_path("recon-ranks.ivol");
    const std::vector<RankOutcome> ranks = run_ranks(scan, 3, path, options, slab, mailbox);
    std::uint64_t slices = 0;
    for (std::size_t r = 0; r < ranks.size(); ++r) {
      EXPECT_EQ(ranks[r].error, "") << "rank " << r;
      EXPECT_EQ(ranks[r].built.slabs_built, kind == kBrickedLayers ? 1U : 3U) << "rank " << r;
      slices += ranks[r].built.slices_built;
    }
    EXPECT_EQ(slices, scan.grid.size[2]);
    EXPECT_EQ(ranks[0].built.written.slab_slices, slab);
    EXPECT_EQ(ranks[0].built.written.structure, kind >= kBricked ? "bricked" : "octree");
    // float32 as binary16, counted on every rank; float32 as it is
    EXPECT_EQ(ranks[0].built.written.lossless, kind == kBrickedFloat32);
    EXPECT_EQ(ranks[0].built.written.max_abs_error > 0.0, kind != kBrickedFloat32);
    EXPECT_GT(mailbox.bytes_to_rank0, 0U);
    EXPECT_EQ(test::read_bytes(path), test::read_bytes(one_path)) << "kind " << kind;
  }
}

TEST(ReconBuiltSlabs, WriterSlabsGiveEveryRankOne) {
  StreamingOptions options;  // 512 MiB of budget: the writer would take the whole volume
  EXPECT_EQ(convert::distributed_slab_slices(Dims{40, 36, 33}, options, 1, 0), 64U);
  EXPECT_EQ(convert::distributed_slab_slices(Dims{40, 36, 33}, options, 2, 0), 32U);  // 2 slabs
  EXPECT_EQ(convert::distributed_slab_slices(Dims{40, 36, 33}, options, 4, 0), 8U);   // 5 slabs
  EXPECT_EQ(convert::distributed_slab_slices(Dims{40, 36, 33}, options, 2, 3), 2U);   // at most 3: 2
  EXPECT_EQ(convert::distributed_slab_slices(Dims{4, 4, 2}, options, 8, 0), 1U);      // never below one slice
}

TEST(ReconBuiltSlabs, RankFailingWhileBuildingEndsTheRun) {
  Scan scan;
  for (const bool bricked : {false, true}) {
    convert::ImportOptions options;
    options.structure = bricked ? convert::StructureChoice::Auto : convert::StructureChoice::Octree;
    const std::string path = test::temp_path("recon-fails.ivol");
    std::filesystem::remove(path);
    ::setenv("IVOL_TEST_FAIL_BUILD_RANK", "2", 1);
    Mailbox mailbox;
    const std::vector<RankOutcome> ranks = run_ranks(scan, 3, path, options, 4, mailbox);
    ::unsetenv("IVOL_TEST_FAIL_BUILD_RANK");
    const std::string step = bricked ? "storing the values of slab 2" : "building the subtrees of slab 2";
    EXPECT_EQ(ranks[0].error, "rank 2: " + step + ": failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
    EXPECT_EQ(ranks[2].error, step + ": failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
    EXPECT_EQ(ranks[1].error, "");
    EXPECT_FALSE(std::filesystem::exists(path));
    const std::string directory = std::filesystem::path(path).parent_path().string();
    for (const auto& entry : std::filesystem::directory_iterator(directory))
      EXPECT_EQ(entry.path().filename().string().rfind(".recon-fails.ivol.tmp-", 0), std::string::npos)
          << entry.path() << " left behind";
  }
}

TEST(ReconBuiltSlabs, LayerSlabsGiveEveryRankOne) {
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 33, 1, 0), 32U);  // layers of 32 and 1
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 33, 2, 0), 32U);  // 2 slabs already
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 33, 4, 0), 8U);   // 16, 16 and 1 are 3: 4 x 8 and 1
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 33, 2, 3), 2U);   // at most 3: 2
  EXPECT_EQ(convert::distributed_layer_slab_slices(24, 24, 4, 0), 6U);   // a layer of 24 in 4
  EXPECT_EQ(convert::distributed_layer_slab_slices(2, 2, 8, 0), 1U);     // never below one slice
  // Whole layers, as many as the bound holds, while every rank has a slab.
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 256, 2, 128), 128U);
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 256, 4, 128), 64U);
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 256, 16, 1000), 16U);
  EXPECT_EQ(convert::distributed_layer_slab_slices(32, 100, 1, 96), 64U);  // 64 and 36
}

TEST(ReconBuiltStructure, SameOctreeFileAsOneProcess) {
  Scan scan;
  const std::unique_ptr<VoxelStructure> structure = two_cube_octree(scan.grid.size);
  const std::string one_path = test::temp_path("structure-one.ivol");
  {
    recon::FdkReconstructor reconstructor(scan.projections, scan.geometry);
    reconstructor.reconstruct_structure(scan.grid, *structure);
    write_structure(*structure, one_path, Metadata{});  // the writer's own slabs: one, of 64 slices
  }
  // Writer slabs of 2 slices (17 of them, at least 4 per rank, 6, 6 and 5);
  // leaves up to 32 tall, fine bricks of 8 cut to the slabs.
  Mailbox mailbox;
  const std::string path = test::temp_path("structure-ranks.ivol");
  const std::vector<StructureRankOutcome> ranks = run_structure_ranks(scan, 3, *structure, path, mailbox);
  std::uint64_t slices = 0, part_voxels = 0;
  for (std::size_t r = 0; r < ranks.size(); ++r) {
    EXPECT_EQ(ranks[r].error, "") << "rank " << r;
    EXPECT_EQ(ranks[r].built.slabs_built, r < 2 ? 6U : 5U) << "rank " << r;
    EXPECT_LT(ranks[r].built.part_voxels, structure->voxel_count()) << "rank " << r << " reconstructed everything";
    slices += ranks[r].built.slices_built;
    part_voxels += ranks[r].built.part_voxels;
  }
  EXPECT_EQ(slices, scan.grid.size[2]);
  EXPECT_GT(part_voxels, structure->voxel_count());  // tall leaves on several ranks
  EXPECT_EQ(ranks[0].built.slab_slices, 2U);
  EXPECT_GT(mailbox.bytes_to_rank0, 0U);
  EXPECT_EQ(test::read_bytes(path), test::read_bytes(one_path));
}

TEST(ReconBuiltStructure, RankFailingWhileBuildingEndsTheRun) {
  Scan scan;
  const std::unique_ptr<VoxelStructure> structure = two_cube_octree(scan.grid.size);
  const std::string path = test::temp_path("structure-fails.ivol");
  std::filesystem::remove(path);
  ::setenv("IVOL_TEST_FAIL_BUILD_RANK", "1", 1);
  Mailbox mailbox;
  const std::vector<StructureRankOutcome> ranks = run_structure_ranks(scan, 3, *structure, path, mailbox);
  ::unsetenv("IVOL_TEST_FAIL_BUILD_RANK");
  EXPECT_EQ(ranks[0].error, "rank 1: building the subtrees of slab 1: failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
  EXPECT_EQ(ranks[1].error, "building the subtrees of slab 1: failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
  EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace
}  // namespace ivol
