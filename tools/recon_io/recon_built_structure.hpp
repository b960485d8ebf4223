// A distributed reconstruction into an octree structure (`recon --structure
// octree` under mpirun) that fills and builds the structure where it is
// reconstructed, as recon_built_slabs.hpp does for the dense path
// (docs/distributed.md).
//
// The volume is cut into the octree writer's slabs, handed out round robin.
// Each rank takes the part of the structure that its slabs meet
// (structure_part: fine bricks cut to its slabs, coarse leaves whole),
// reconstructs it in one pass, so that each
// detector row it needs is filtered once, fills each of its slabs from it as
// soon as the slab's bricks are final (OctreeSlabFiller), builds the slab's
// subtrees (OctreeSlabBuilder) and sends them to rank 0. Rank 0 adds every
// slab to its writer in z order, its own and the others' as they come, builds
// the levels above the subtrees and writes the file.
//
// The file is the single process's, bit for bit: a brick's value does not
// depend on which other bricks are reconstructed with it (each is its own
// task or its own lanes of one, summed over the views in the same order), the
// slabs are filled and built as the single process's writer fills them, and
// the writer's slab thickness does not change the file. A coarse leaf taller
// than a slab meets the slabs of several ranks; each of them reconstructs it
// (8 samples), which the ranks' voxel updates count.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/slab_exchange.hpp"
#include "ivol/structure_stream.hpp"
#include "ivol/structures.hpp"

namespace ivol::convert {

struct DistributedStructureBuild {
  recon::FdkReport fdk;            // this rank's part
  StreamingResult written;         // rank 0 only
  std::uint64_t part_voxels = 0;   // the voxels of this rank's part (tall leaves in several parts)
  std::uint64_t slabs_built = 0;   // the writer's slabs this rank filled and built
  std::uint64_t slices_built = 0;  // their slices
  std::uint32_t slab_slices = 0;   // the writer's slab thickness
  std::uint64_t value_window_peak_bytes = 0;
  double build_seconds = 0;       // filling and building this rank's slabs
  double writing_seconds = 0;     // rank 0: adding slabs, the levels above, the file
  double waiting_seconds = 0;     // rank 0: waiting for the other ranks' slabs
  double during_fdk_seconds = 0;  // of those three, inside the FDK's slab hand-over
};

struct DistributedStructureOptions {
  StreamingOptions streaming;                 // the writer's; its slab thickness is chosen here
  std::uint32_t most_slab_slices = 0;         // --slab-slices (0: no bound)
  std::uint64_t value_window_bytes = 0;       // the values in flight (0: no bound)
  Metadata metadata;                          // rank 0's file
  std::function<void(Metadata&)> complete;    // rank 0, after the last slab (the sources' digests)
  std::function<void()> every_slab_received;  // rank 0, once every slab is in
};

// This rank's part; collective over `exchange`'s ranks. `structure` must be
// an octree, the same on every rank, and `reconstructor` must have no
// exchange of its own. Rank 0 writes `path`; a rank other than 0 that fails
// tells rank 0, which throws "rank K: …" and removes its temporary file.
DistributedStructureBuild reconstruct_structure_distributed(recon::FdkReconstructor& reconstructor,
                                                            const recon::VolumeGrid& grid,
                                                            const VoxelStructure& structure, const std::string& path,
                                                            const DistributedStructureOptions& options,
                                                            recon::SlabExchange& exchange);

}  // namespace ivol::convert
