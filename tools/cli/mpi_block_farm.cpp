#include "mpi_block_farm.hpp"

#include <mpi.h>

#include <chrono>
#include <cstdlib>
#include <exception>
#include <stdexcept>
#include <string>
#include <thread>

#include "mpi_messages.hpp"
#include "wire.hpp"

namespace ivol::cli {
namespace {

// Blocks per rank in a batch: 64 blocks of 16 KiB make 1 MiB messages, large
// enough that a message's latency is small against compressing it, small
// enough that rank 0 holds only a few MiB of blocks at a time.
constexpr std::size_t kBlocksPerRank = 64;

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

using Packer = convert::BasicWireWriter<std::vector<std::uint8_t>>;
using Unpacker = convert::BasicWireReader<std::vector<std::uint8_t>>;

// Only the options encode_block's output depends on travel.
std::vector<std::uint8_t> pack_batch(const RawBlock* blocks, std::size_t count, const WriteOptions& options) {
  Packer p;
  p.put<std::uint64_t>(count);
  p.put<std::int32_t>(options.zstd_level);
  p.put<std::uint8_t>(options.compress ? 1 : 0);
  p.put<std::uint8_t>(options.byte_planes ? 1 : 0);
  p.put<std::uint8_t>(options.framed_blocks ? 1 : 0);  // format 1.3: codec 5 from level 13
  for (std::size_t i = 0; i < count; ++i) {
    const RawBlock& b = blocks[i];
    p.put<std::uint8_t>(static_cast<std::uint8_t>(b.stream));
    p.put<std::uint8_t>(b.level);
    p.put<std::uint32_t>(b.width);
    p.put<std::uint64_t>(b.first_element);
    p.put<std::uint32_t>(b.element_count);
    p.put_bytes(b.bytes);
  }
  return std::move(p.bytes());
}

std::vector<RawBlock> unpack_batch(std::vector<std::uint8_t> bytes, WriteOptions& options) {
  Unpacker u(std::move(bytes));
  std::vector<RawBlock> blocks(u.get<std::uint64_t>());
  options.zstd_level = u.get<std::int32_t>();
  options.compress = u.get<std::uint8_t>() != 0;
  options.byte_planes = u.get<std::uint8_t>() != 0;
  options.framed_blocks = u.get<std::uint8_t>() != 0;
  for (RawBlock& b : blocks) {
    b.stream = static_cast<Stream>(u.get<std::uint8_t>());
    b.level = u.get<std::uint8_t>();
    b.width = u.get<std::uint32_t>();
    b.first_element = u.get<std::uint64_t>();
    b.element_count = u.get<std::uint32_t>();
    b.bytes = u.get_bytes();
  }
  return blocks;
}

std::vector<std::uint8_t> pack_encoded(const std::vector<EncodedBlock>& blocks) {
  Packer p;
  p.put<std::uint64_t>(blocks.size());
  for (const EncodedBlock& b : blocks) {
    p.put<std::uint8_t>(static_cast<std::uint8_t>(b.codec));
    p.put<std::uint32_t>(b.crc);
    p.put_bytes(b.bytes);
  }
  return std::move(p.bytes());
}

// The compressed blocks of raw[0 .. count), whose descriptions rank 0 kept.
void unpack_encoded(std::vector<std::uint8_t> bytes, const RawBlock* raw, std::size_t count, EncodedBlock* out) {
  Unpacker u(std::move(bytes));
  if (u.get<std::uint64_t>() != count) throw std::runtime_error("a rank returned the wrong number of blocks");
  for (std::size_t i = 0; i < count; ++i) {
    EncodedBlock& b = out[i];
    b.stream = raw[i].stream;
    b.level = raw[i].level;
    b.first_element = raw[i].first_element;
    b.element_count = raw[i].element_count;
    b.codec = static_cast<Codec>(u.get<std::uint8_t>());
    b.crc = u.get<std::uint32_t>();
    b.bytes = u.get_bytes();
  }
}

// For the failure test of tests/cli/run_mpi.sh: the rank this names fails
// when its first batch arrives.
bool failure_injected(int rank) {
  const char* value = std::getenv("IVOL_TEST_FAIL_COMPRESSION_RANK");
  return value != nullptr && std::atoi(value) == rank;
}

}  // namespace

struct MpiBlockFarm::Impl {
  std::shared_ptr<recon::SlabExchange> exchange;
  int rank = 0;
  int size = 1;
  std::thread::id mpi_thread = std::this_thread::get_id();
  std::vector<bool> ready;         // rank 0: which ranks take batches
  std::exception_ptr ready_error;  // a rank failed instead of getting ready
  CompressionStats stats;

  std::vector<EncodedBlock> encode_here(const RawBlock* blocks, std::size_t count, const WriteOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    std::vector<EncodedBlock> encoded = encode_blocks(blocks, count, options);
    stats.seconds += seconds_since(start);
    stats.blocks += count;
    for (std::size_t i = 0; i < count; ++i) stats.input_bytes += blocks[i].bytes.size();
    for (const EncodedBlock& b : encoded) stats.output_bytes += b.bytes.size();
    return encoded;
  }

  // Waits until every rank has said it is ready.
  void await_every_rank() {
    note_ready_ranks();
    for (int r = 1; r < size; ++r) {
      if (ready[static_cast<std::size_t>(r)]) continue;
      mpi::wait_for(r, mpi::kReadyTag);
      int ignored = 0;
      MPI_Recv(&ignored, 1, MPI_INT, r, mpi::kReadyTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      ready[static_cast<std::size_t>(r)] = true;
    }
  }

  // Ranks that have said they are ready since the last look.
  void note_ready_ranks() {
    for (;;) {
      int arrived = 0;
      MPI_Status status;
      MPI_Iprobe(MPI_ANY_SOURCE, mpi::kReadyTag, MPI_COMM_WORLD, &arrived, &status);
      if (!arrived) return;
      int ignored = 0;
      MPI_Recv(&ignored, 1, MPI_INT, status.MPI_SOURCE, mpi::kReadyTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      ready[static_cast<std::size_t>(status.MPI_SOURCE)] = true;
    }
  }

  // On the MPI thread: one contiguous share of the batch per ready rank and
  // one for rank 0, the first.
  std::vector<EncodedBlock> distribute(const std::vector<RawBlock>& batch, const WriteOptions& options) {
    if (ready_error) std::rethrow_exception(ready_error);
    note_ready_ranks();
    std::vector<int> helpers;
    for (int r = 1; r < size; ++r)
      if (ready[static_cast<std::size_t>(r)]) helpers.push_back(r);
    const std::size_t shares = helpers.size() + 1;
    auto share_begin = [&](std::size_t s) { return batch.size() * s / shares; };
    for (std::size_t s = 1; s < shares; ++s) {
      if (share_begin(s) == share_begin(s + 1)) continue;
      stats.bytes_sent +=
          mpi::send_bytes(pack_batch(batch.data() + share_begin(s), share_begin(s + 1) - share_begin(s), options),
                          helpers[s - 1], mpi::kBatchTag);
    }
    std::vector<EncodedBlock> encoded = encode_here(batch.data(), share_begin(1), options);
    encoded.resize(batch.size());
    std::vector<std::uint8_t> message;
    for (std::size_t s = 1; s < shares; ++s) {
      if (share_begin(s) == share_begin(s + 1)) continue;
      mpi::wait_for(helpers[s - 1], mpi::kEncodedTag);
      stats.bytes_received += mpi::receive_bytes(message, helpers[s - 1], mpi::kEncodedTag);
      unpack_encoded(std::move(message), batch.data() + share_begin(s), share_begin(s + 1) - share_begin(s),
                     encoded.data() + share_begin(s));
    }
    return encoded;
  }
};

MpiBlockFarm::MpiBlockFarm(std::shared_ptr<recon::SlabExchange> exchange) : impl_(std::make_unique<Impl>()) {
  impl_->exchange = std::move(exchange);
  impl_->rank = impl_->exchange->rank();
  impl_->size = impl_->exchange->size();
  impl_->ready.assign(static_cast<std::size_t>(impl_->size), false);
}

MpiBlockFarm::~MpiBlockFarm() = default;

std::size_t MpiBlockFarm::batch_blocks() const { return kBlocksPerRank * static_cast<std::size_t>(impl_->size); }

std::vector<EncodedBlock> MpiBlockFarm::encode(const std::vector<RawBlock>& batch, const WriteOptions& options) {
  Impl& m = *impl_;
  if (m.rank != 0) throw std::logic_error("only rank 0 writes");
  if (std::this_thread::get_id() != m.mpi_thread) throw std::logic_error("MPI is called from one thread only");
  return m.distribute(batch, options);
}

void MpiBlockFarm::every_slab_received() {
  Impl& m = *impl_;
  try {
    m.await_every_rank();
  } catch (...) {
    // The writer's next batch fails with the rank's message.
    m.ready_error = std::current_exception();
  }
}

void MpiBlockFarm::release() {
  Impl& m = *impl_;
  if (m.ready_error) std::rethrow_exception(m.ready_error);
  m.await_every_rank();
  for (int r = 1; r < m.size; ++r) {
    const int done = 0;
    MPI_Send(&done, 1, MPI_INT, r, mpi::kDoneTag, MPI_COMM_WORLD);
  }
}

void MpiBlockFarm::work() {
  Impl& m = *impl_;
  const int me = m.rank;
  MPI_Send(&me, 1, MPI_INT, 0, mpi::kReadyTag, MPI_COMM_WORLD);
  std::vector<std::uint8_t> message;
  try {
    for (;;) {
      MPI_Status status;
      MPI_Probe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &status);
      if (status.MPI_TAG == mpi::kDoneTag) {
        int ignored = 0;
        MPI_Recv(&ignored, 1, MPI_INT, 0, mpi::kDoneTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        return;
      }
      if (status.MPI_TAG != mpi::kBatchTag)
        throw std::runtime_error("unexpected message (tag " + std::to_string(status.MPI_TAG) + ") from rank 0");
      m.stats.bytes_received += mpi::receive_bytes(message, 0, mpi::kBatchTag);
      WriteOptions options;
      const std::vector<RawBlock> batch = unpack_batch(std::move(message), options);
      if (failure_injected(me))
        throw std::runtime_error("failure injected for testing (IVOL_TEST_FAIL_COMPRESSION_RANK=" + std::to_string(me) +
                                 ")");
      const std::vector<EncodedBlock> encoded = m.encode_here(batch.data(), batch.size(), options);
      m.stats.bytes_sent += mpi::send_bytes(pack_encoded(encoded), 0, mpi::kEncodedTag);
    }
  } catch (const std::exception& e) {
    const std::string what = std::string("compressing blocks for rank 0: ") + e.what();
    m.exchange->report_failure(what);
    throw std::runtime_error(what);
  }
}

const CompressionStats& MpiBlockFarm::stats() const { return impl_->stats; }

}  // namespace ivol::cli
