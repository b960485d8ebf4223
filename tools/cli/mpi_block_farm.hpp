// Compressing a distributed run's blocks on every rank (docs/distributed.md).
//
// Rank 0 writes the file, but zstd is the heavy part of writing: given as
// WriteOptions::encoder, the farm cuts each batch of blocks the writer
// collects into one share per rank that is ready, sends the shares, compresses
// its own, and takes the others' back in order. The other ranks join once
// their slabs are sent (work()); until then rank 0 compresses alone (the
// structure path writes while slabs arrive). The
// file is the same bit for bit (ivol/block_encoder.hpp).
//
// MPI is called from the thread that made the farm only (MPI_THREAD_FUNNELED):
// rank 0's writer runs on that thread (the dense path's and the structures').
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "ivol/block_encoder.hpp"
#include "ivol/recon/slab_exchange.hpp"

namespace ivol::cli {

// What one rank compressed, and the batches' traffic.
struct CompressionStats {
  std::uint64_t blocks = 0;
  std::uint64_t input_bytes = 0;  // the blocks' bytes before compression
  std::uint64_t output_bytes = 0;
  double seconds = 0;  // compressing, on this rank's threads
  std::uint64_t bytes_sent = 0;
  std::uint64_t bytes_received = 0;
};

class MpiBlockFarm final : public BlockEncoder {
 public:
  // `exchange` carries a failure on another rank to rank 0.
  explicit MpiBlockFarm(std::shared_ptr<recon::SlabExchange> exchange);
  ~MpiBlockFarm() override;
  MpiBlockFarm(const MpiBlockFarm&) = delete;
  MpiBlockFarm& operator=(const MpiBlockFarm&) = delete;

  // Rank 0, BlockEncoder: on the farm's thread. Throws "rank K: …" when a
  // rank fails while compressing.
  std::size_t batch_blocks() const override;
  std::vector<EncodedBlock> encode(const std::vector<RawBlock>& batch, const WriteOptions& options) override;

  // Rank 0, on the farm's thread, once its reconstruction has received every
  // slab: the other ranks are about to be ready; waits for them, so that
  // every later batch is shared by all ranks.
  void every_slab_received();

  // Rank 0, once the file is written: waits for every rank to be ready and
  // tells each that no more batches come.
  void release();
  // The other ranks, once their slabs are sent: compress rank 0's batches
  // until it releases them. A failure is sent to rank 0 and thrown.
  void work();

  const CompressionStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ivol::cli
