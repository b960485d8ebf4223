// A distributed dense reconstruction into a bricked regular grid
// (bricked_import.hpp; docs/distributed.md). The volume is cut into slabs of
// whole layers of bricks, as many as one process would read at once, or
// into slabs that divide a layer, handed out round robin. Each rank
// reconstructs its slabs and turns them into the stored 16-bit values there
// (binary16, half the bytes of the float32 samples), counting what the
// rounding changes; rank 0 gathers each layer from its slabs, its own and
// the others', adds it to the writer in z order, merges the counts, and
// writes the file: the same file, bit for bit, as import_to_ivol writes in
// one process (a voxel's value does not depend on how the volume is cut,
// and the writer sees the same layers). Rank 0's writer encodes the bricks
// on its own threads.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "ivol/recon/fdk.hpp"
#include "ivol/recon/slab_exchange.hpp"
#include "recon_built_slabs.hpp"

namespace ivol::convert {

// The slab thickness: whole layers, as many as `most_slices` holds (a power
// of two of them; 0: one layer), halved until every rank has a slab (a
// layer's slices too, while slabs are thicker than one slice) and until it
// is at most `most_slices`.
std::uint32_t distributed_layer_slab_slices(std::uint32_t layer_slices, std::uint32_t depth, int ranks,
                                            std::uint32_t most_slices);

// This rank's part; collective over `exchange`'s ranks, which must all have
// chosen a bricked grid (choose_bricked). As reconstruct_distributed.
DistributedBuild reconstruct_distributed_bricked(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                                 const std::string& path, const ImportOptions& options,
                                                 recon::SlabExchange& exchange, std::uint32_t most_slab_slices,
                                                 const std::function<void()>& every_slab_received);

}  // namespace ivol::convert
