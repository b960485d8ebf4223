// `mpirun -np N ivol recon …`: the ranks of a distributed reconstruction
// (docs/distributed.md). recon stays free of MPI; this file gives it a
// SlabExchange over MPI. Rank 0 receives every slab, writes the file and
// prints the report; the other ranks reconstruct their slabs and send them
// (a dense volume's as built octree subtrees, recon_io/recon_built_slabs.hpp;
// a structure's as sums), then compress blocks of the file for rank 0
// (mpi_block_farm.hpp).
//
// MPI is used from the main thread only (MPI_THREAD_FUNNELED): slabs are
// sent and received there (the FDK's consume loop for structures, the loop of
// convert::reconstruct_distributed for dense volumes), and rank 0's writer,
// whose batches of blocks go to the other ranks, runs there too.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/block_encoder.hpp"
#include "ivol/recon/slab_exchange.hpp"

namespace ivol::cli {

// What one rank did, gathered on rank 0 for the report.
struct RankStats {
  double seconds = 0;         // from the start of the command to the end of its work
  double backprojection = 0;  // seconds in backprojection kernels
  std::uint64_t voxel_updates = 0;
  std::uint64_t bytes_sent = 0;      // slab data to rank 0 (and failures), and block_bytes_sent
  std::uint64_t bytes_received = 0;  // slab data from the other ranks (rank 0), and block_bytes_received
  std::uint64_t slabs_sent = 0;
  // The slabs alone (float32 samples, or built subtrees in the dense path),
  // without the blocks' traffic.
  std::uint64_t slab_bytes_sent = 0;
  std::uint64_t slab_bytes_received = 0;
  // Dense path: the writer's slabs this rank reconstructed and built into
  // octree subtrees, their slices (margins not counted), and its seconds in
  // building them.
  std::uint64_t slabs_built = 0;
  std::uint64_t slices_built = 0;
  double build_seconds = 0;
  // Compressing the file's blocks (mpi_block_farm.hpp): how many this rank
  // compressed, their bytes before and after, its seconds in zstd, and the
  // blocks' traffic (raw to the ranks, compressed back to rank 0).
  std::uint64_t blocks_compressed = 0;
  std::uint64_t compression_input_bytes = 0;
  std::uint64_t compression_output_bytes = 0;
  double compression_seconds = 0;
  std::uint64_t block_bytes_sent = 0;
  std::uint64_t block_bytes_received = 0;
};

class MpiRun {
 public:
  // Whether this process is one of several started by mpirun (Open MPI's
  // OMPI_COMM_WORLD_SIZE, or PMI_SIZE from Slurm or MPICH, above 1).
  static bool launched();
  // Whether this ivol was built with MPI (IVOL_WITH_MPI).
  static bool available();

  // MPI_Init_thread (MPI_THREAD_FUNNELED). mpirun sends SIGTERM to every
  // rank when one of them dies: signal_cleanup.hpp (started in main) removes
  // each rank's temporary output files then. Throws when built without MPI.
  MpiRun();
  ~MpiRun();  // MPI_Finalize
  MpiRun(const MpiRun&) = delete;
  MpiRun& operator=(const MpiRun&) = delete;

  int rank() const;
  int size() const;
  std::shared_ptr<recon::SlabExchange> exchange() const;

  // Distributed compression, mpi_block_farm.hpp. Rank 0: the writer's
  // WriteOptions::encoder, every_slab_received() when its reconstruction is
  // done (so that all ranks share the batches after it), and, once the file
  // is written, end_compression() to let the other ranks go. The other
  // ranks: serve_compression() once their slabs are sent, until rank 0 ends it.
  std::shared_ptr<BlockEncoder> block_encoder() const;
  void every_slab_received();
  void end_compression();
  void serve_compression();

  // Collective: every rank's stats on rank 0, rank by rank (empty elsewhere).
  // Bytes, slabs and compression come from the exchange and the farm.
  std::vector<RankStats> gather(RankStats mine);

  // Ends the whole run after `what` failed on this rank: prints
  // "ivol recon: error: …" (rank 0, which reports the other ranks' failures
  // as "rank K: …") or "ivol recon: rank K: error: …", and MPI_Abort with kExitFailure. A
  // rank whose failure rank 0 already has waits for rank 0 to end the run,
  // so that rank 0 removes its temporary file before anything is killed.
  [[noreturn]] void fail(const std::exception& what);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ivol::cli
