#include "recon_built_structure.hpp"

#include <chrono>
#include <map>
#include <stdexcept>
#include <vector>

#include "ivol/octree_slab_builder.hpp"
#include "ivol/streaming_writer.hpp"
#include "recon_built_slabs.hpp"

namespace ivol::convert {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Rank 0's writer: slabs in z order, its own as they are built (held until
// every slab below them is in) and the other ranks' as they come.
class SlabAssembly {
 public:
  SlabAssembly(StreamingOctreeWriter& writer, const OctreeSlabBuilder& builder, recon::SlabExchange& exchange,
               DistributedStructureBuild& result)
      : writer_(writer), builder_(builder), exchange_(exchange), result_(result) {}

  void own(std::uint32_t slab, BuiltSlab built) {
    held_.emplace(slab, std::move(built));
    add_ready();
  }
  // Adds every slab it can: the other ranks' are waited for, its own only
  // once built. With `all`, every slab must now be built.
  void add_ready(bool all = false) {
    for (; next_ < builder_.slab_count(); ++next_) {
      const int from = exchange_.owner(next_, builder_.slab_count());
      BuiltSlab built;
      if (from == 0) {
        auto mine = held_.find(next_);
        if (mine == held_.end()) {
          if (all) throw std::logic_error("distributed structure: rank 0's slab " + std::to_string(next_) + " missing");
          return;
        }
        built = std::move(mine->second);
        held_.erase(mine);
      } else {
        const auto waiting = std::chrono::steady_clock::now();
        exchange_.receive_bytes(next_, from, built.bytes);
        result_.waiting_seconds += seconds_since(waiting);
      }
      const auto adding = std::chrono::steady_clock::now();
      writer_.add_built_slab(built);
      result_.writing_seconds += seconds_since(adding);
    }
  }

 private:
  StreamingOctreeWriter& writer_;
  const OctreeSlabBuilder& builder_;
  recon::SlabExchange& exchange_;
  DistributedStructureBuild& result_;
  std::map<std::uint32_t, BuiltSlab> held_;
  std::uint32_t next_ = 0;
};

// A structure's voxels are not spread evenly along z (the object is where
// it is), so each rank takes several slabs, spread over the volume: at
// 256³ with 2 ranks, one slab each gave the pencil holder's rank 0 80 % of
// the voxel updates. Thinner slabs cost little: fine bricks are cut to a
// rank's slabs, and only coarse leaves taller than a slab are reconstructed
// on more than one rank (8 samples each).
constexpr unsigned kSlabsPerRank = 4;

}  // namespace

DistributedStructureBuild reconstruct_structure_distributed(recon::FdkReconstructor& reconstructor,
                                                            const recon::VolumeGrid& grid,
                                                            const VoxelStructure& structure, const std::string& path,
                                                            const DistributedStructureOptions& options,
                                                            recon::SlabExchange& exchange) {
  if (structure.kind() != StructureKind::Octree)
    throw std::logic_error("a distributed structure build is for octrees (the grids share compression only)");
  const Dims& dims = structure.dims();
  DistributedStructureBuild result;
  StreamingOptions streaming = options.streaming;
  streaming.slab_slices = static_cast<std::uint32_t>(
      exchange.agree(distributed_slab_slices(dims, streaming, exchange.size(), options.most_slab_slices,
                                             kSlabsPerRank),
                     "the writer's slab thickness in slices"));
  const OctreeSlabBuilder builder(dims, streaming);
  result.slab_slices = builder.slab_slices();
  const std::uint32_t slab_count = builder.slab_count();
  const bool injected_failure = rank_told_to_fail_building() == exchange.rank();

  std::vector<std::uint32_t> mine;
  std::vector<SliceRange> ranges;
  for (std::uint32_t k = 0; k < slab_count; ++k)
    if (exchange.owner(k, slab_count) == exchange.rank()) {
      mine.push_back(k);
      ranges.push_back({builder.slab_first(k), builder.slab_first(k) + builder.slab_size(k)});
    }
  const std::unique_ptr<VoxelStructure> part = structure_part(structure, ranges);
  result.part_voxels = part->voxel_count();

  std::unique_ptr<StreamingOctreeWriter> writer;
  std::unique_ptr<SlabAssembly> assembly;
  if (exchange.rank() == 0) {
    writer = std::make_unique<StreamingOctreeWriter>(path, dims, streaming);
    assembly = std::make_unique<SlabAssembly>(*writer, builder, exchange, result);
  }
  StructureValueWindow values(*part);
  OctreeSlabFiller filler(*part);
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  std::vector<float> samples(slice * builder.slab_slices());
  std::vector<std::uint8_t> keep(samples.size());
  std::size_t next_mine = 0;
  // Fills and builds every slab of this rank whose bricks are all final.
  auto build_ready = [&](std::uint32_t z_complete) {
    const auto began = std::chrono::steady_clock::now();
    struct Timed {
      double& into;
      std::chrono::steady_clock::time_point began;
      ~Timed() { into += seconds_since(began); }
    } timed{result.during_fdk_seconds, began};
    for (; next_mine < mine.size() && ranges[next_mine].end <= z_complete; ++next_mine) {
      const std::uint32_t k = mine[next_mine];
      const auto building = std::chrono::steady_clock::now();
      filler.fill(ranges[next_mine].first, ranges[next_mine].end, values, samples.data(), keep.data());
      values.release_below(ranges[next_mine].end);
      if (injected_failure)
        throw std::runtime_error("building the subtrees of slab " + std::to_string(k) +
                                 ": failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
      BuiltSlab built = builder.build(k, samples.data(), keep.data());
      result.build_seconds += seconds_since(building);
      ++result.slabs_built;
      result.slices_built += builder.slab_size(k);
      if (assembly)
        assembly->own(k, std::move(built));
      else
        exchange.send_bytes(k, built.bytes);
    }
  };

  try {
    recon::FdkReconstructor::ValueWindowBound window;
    window.memory_limit = options.value_window_bytes;
    window.writer_slab_slices = builder.slab_slices();
    result.fdk = reconstructor.reconstruct_structure(grid, *part, values, build_ready, window);
    const double inside = result.during_fdk_seconds;
    build_ready(dims[2]);  // what the last hand-over left
    result.during_fdk_seconds = inside;
  } catch (const std::exception& error) {
    if (exchange.rank() != 0) exchange.report_failure(error.what());  // rank 0 is waiting for this rank's slabs
    throw;
  }
  result.value_window_peak_bytes = values.peak_bytes();
  if (!assembly) return result;

  assembly->add_ready(true);
  if (options.every_slab_received) options.every_slab_received();
  const auto finishing = std::chrono::steady_clock::now();
  Metadata metadata = options.metadata;
  if (options.complete) options.complete(metadata);
  result.written = writer->finish(metadata);
  result.writing_seconds += seconds_since(finishing);
  return result;
}

}  // namespace ivol::convert
