// The point-to-point messages of a distributed `ivol recon` besides the
// slabs themselves: tags, buffers of any size, and waiting for a message on
// rank 0 while watching for another rank's failure. Compiled with MPI only.
#pragma once

#include <cstdint>
#include <vector>

namespace ivol::cli::mpi {

// Slab tags are 1 .. 30000 (mpi_exchange.cpp); the others lie above.
constexpr int kFailureTag = 32000;  // a rank's error message, to rank 0
constexpr int kReadyTag = 32001;    // a rank done with its slabs, ready to compress blocks
constexpr int kBatchTag = 32002;    // rank 0 to a rank: blocks to compress
constexpr int kEncodedTag = 32003;  // back to rank 0: the compressed blocks
constexpr int kDoneTag = 32004;     // rank 0 to a rank: no more batches

// On rank 0: returns once a message `tag` from rank `from` has arrived.
// Throws std::runtime_error "rank K: <message>" when some rank K reported a
// failure first (the failed rank need not be `from`).
void wait_for(int from, int tag);

// A buffer of any size: its length, then pieces below 2³¹ bytes (MPI counts
// are ints). Both return the bytes that went over the wire.
std::uint64_t send_bytes(const std::vector<std::uint8_t>& bytes, int to, int tag);
std::uint64_t receive_bytes(std::vector<std::uint8_t>& bytes, int from, int tag);

}  // namespace ivol::cli::mpi
