// Distributing a reconstruction over several processes (ranks), without
// recon knowing how they talk: the caller supplies an exchange (tools/cli has
// one over MPI) in FdkOptions::exchange.
//
// Every rank runs the same reconstruction of the same grid. Each produces
// only the slabs it owns (owner()), reading only the detector rows those
// slabs need, and sends them to rank 0; rank 0 hands every slab to its sink
// in increasing z, its own and the others', exactly as a single process
// would. A voxel's value does not depend on how the volume was cut into
// slabs, so the result is the same bit for bit whatever the number of ranks.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ivol::recon {

class SlabExchange {
 public:
  virtual ~SlabExchange() = default;

  virtual int rank() const = 0;
  virtual int size() const = 0;
  // The rank that produces slab `slab` of `count`: round robin, which keeps
  // every rank busy and each rank's memory to one or two slabs.
  virtual int owner(std::size_t slab, std::size_t /*count*/) const { return static_cast<int>(slab % size()); }

  // Collective: rank 0's value, on every rank. Throws std::runtime_error on
  // every rank, naming `what` and the ranks' values, when any rank's value
  // differs from rank 0's (the ranks would cut the volume differently).
  virtual std::uint64_t agree(std::uint64_t value, const std::string& what) = 0;
  // Collective: rank 0's values (and size) on every rank.
  virtual void broadcast(std::vector<float>& values) = 0;

  // From the slab's owner to rank 0, in increasing slab order per rank.
  virtual void send(std::size_t slab, const std::vector<float>& data) = 0;
  // On rank 0: slab `slab` from rank `from`, `data` resized to what was sent.
  // Throws std::runtime_error "rank K: <message>" when any rank reported a
  // failure instead.
  virtual void receive(std::size_t slab, int from, std::vector<float>& data) = 0;
  // The same for a slab in another form, as bytes: a distributed dense
  // reconstruction sends each slab's built octree subtrees
  // (ivol/octree_slab_builder.hpp) instead of its float32 samples.
  virtual void send_bytes(std::size_t slab, const std::vector<std::uint8_t>& data) = 0;
  virtual void receive_bytes(std::size_t slab, int from, std::vector<std::uint8_t>& data) = 0;
  // A rank other than 0 that failed tells rank 0, which is waiting for its
  // slabs, so that rank 0 fails with the message and leaves nothing behind.
  virtual void report_failure(const std::string& message) = 0;
};

}  // namespace ivol::recon
