// `mpirun -np N ivol recon …`: the ranks of a distributed reconstruction
// (docs/distributed.md). recon stays free of MPI; this file gives it a
// SlabExchange over MPI. Rank 0 receives every slab, writes the file and
// prints the report; the other ranks reconstruct their slabs and send them.
//
// MPI is used from the main thread only (MPI_THREAD_FUNNELED): the FDK's
// consume loop, where slabs are sent and received, runs on the calling
// thread, and rank 0's writer runs on a thread of its own that never calls MPI.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/recon/slab_exchange.hpp"

namespace ivol::cli {

// What one rank did, gathered on rank 0 for the report.
struct RankStats {
  double seconds = 0;         // from the start of the command to the end of its work
  double backprojection = 0;  // seconds in backprojection kernels
  std::uint64_t voxel_updates = 0;
  std::uint64_t bytes_sent = 0;      // slab data to rank 0 (and failures)
  std::uint64_t bytes_received = 0;  // slab data from the other ranks (rank 0)
  std::uint64_t slabs_sent = 0;
};

class MpiRun {
 public:
  // Whether this process is one of several started by mpirun (Open MPI's
  // OMPI_COMM_WORLD_SIZE, or PMI_SIZE from Slurm or MPICH, above 1).
  static bool launched();
  // Whether this ivol was built with MPI (IVOL_WITH_MPI).
  static bool available();

  // MPI_Init_thread (MPI_THREAD_FUNNELED). Blocks SIGTERM and SIGINT for
  // every thread started afterwards and waits for them on a thread of its
  // own, which removes this run's temporary output files (see
  // remove_temporaries_on_signal) before exiting: mpirun sends SIGTERM to
  // every rank when one of them dies. Throws when built without MPI.
  MpiRun();
  ~MpiRun();  // MPI_Finalize
  MpiRun(const MpiRun&) = delete;
  MpiRun& operator=(const MpiRun&) = delete;

  int rank() const;
  int size() const;
  std::shared_ptr<recon::SlabExchange> exchange() const;

  // Collective: every rank's stats on rank 0, rank by rank (empty elsewhere).
  // Bytes and slabs come from the exchange.
  std::vector<RankStats> gather(RankStats mine);

  // After a temporary file for `output` may exist on this rank: on SIGTERM
  // or SIGINT, files ".<name>.tmp-*" next to it made since this run started
  // are removed (libformat's and StagedFile's temporaries are named so).
  void remove_temporaries_on_signal(const std::string& output);

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
