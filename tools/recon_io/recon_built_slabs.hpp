// A distributed dense reconstruction that builds the octree where the volume
// is reconstructed (docs/distributed.md).
//
// The volume is cut into the streaming writer's slabs (2^s slices), handed
// out round robin. Each rank reconstructs its slabs, builds their octree
// subtrees (OctreeSlabBuilder) and sends those to rank 0: binary16 values and
// node words, coarsened regions as one value, instead of float32 samples.
// Rank 0 adds every slab to its writer in z order, its own and the others',
// builds the levels above the subtrees and writes the file: the same file,
// bit for bit, as import_to_ivol writes in one process (the writer's slab
// thickness does not change the file, nor does cutting the reconstruction
// into other slabs change a voxel).
//
// A keep mask grows by `margin` voxels, so a slab's mask needs `margin`
// slices of each neighbour. The owner reconstructs them itself rather than
// receive them: a voxel's value does not depend on how the volume is cut
// (test_fdk), the extra work is 2 · margin slices per slab (3 % for 128
// slices and margin 2), and no rank ever waits for a neighbour's slab.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/slab_exchange.hpp"
#include "ivol_io.hpp"

namespace ivol::convert {

struct DistributedBuild {
  recon::FdkReport fdk;  // this rank's reconstructions (margins included), summed
  ImportReport written;  // rank 0 only
  std::uint64_t slabs_built = 0;
  std::uint64_t slices_built = 0;     // its slabs' own slices, margins not counted
  double reconstruction_seconds = 0;  // in the FDK, margins included
  double build_seconds = 0;           // building this rank's slabs' subtrees
  double writing_seconds = 0;         // rank 0: adding slabs, the levels above, the file
  double waiting_seconds = 0;         // rank 0: waiting for the other ranks' slabs
};

// Reconstructs slices [lo, hi) into `values` (resized to them), adding the
// FDK's report and seconds to `result` (the first slab's report is kept as
// it is: it says the devices and plan).
void reconstruct_slices(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid, std::uint32_t lo,
                        std::uint32_t hi, std::vector<float>& values, DistributedBuild& result);

// The writer's slab thickness for a distributed run: its own choice for the
// volume and options, halved until every rank has `slabs_per_rank` slabs
// (while slabs are thicker than one slice) and until it is at most
// `most_slices` (0: no bound).
std::uint32_t distributed_slab_slices(const Dims& dims, const StreamingOptions& options, int ranks,
                                      std::uint32_t most_slices, unsigned slabs_per_rank = 1);

// The rank (IVOL_TEST_FAIL_BUILD_RANK, for the tests only) that fails while
// building its first slab, or -1.
int rank_told_to_fail_building();

// This rank's part; collective over `exchange`'s ranks. Where import_to_ivol
// would write a bricked grid (choose_bricked), the ranks make its layers
// instead (recon_built_layers.hpp). `reconstructor` must
// have no exchange of its own: each rank reconstructs its slabs by itself.
// Rank 0 writes `path`, calling every_slab_received() once every slab is in
// (then the other ranks can compress its blocks), and options.encoder for its
// blocks on this thread. A rank other than 0 that fails tells rank 0, which
// throws "rank K: …" and removes its temporary file.
DistributedBuild reconstruct_distributed(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                         const std::string& path, const ImportOptions& options,
                                         recon::SlabExchange& exchange, std::uint32_t most_slab_slices,
                                         const std::function<void()>& every_slab_received);

}  // namespace ivol::convert
