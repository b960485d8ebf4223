#include "mpi_exchange.hpp"


#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <stdexcept>
#include <thread>

#include "commands.hpp"
#include "ivol/error.hpp"

#ifdef IVOL_WITH_MPI
#include <mpi.h>

#include "mpi_block_farm.hpp"
#include "mpi_messages.hpp"
#endif

namespace ivol::cli {
namespace {

int environment_size(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr ? std::atoi(value) : 0;
}

// How many processes the launcher started, as it says in the environment:
// Open MPI's mpirun, a PMI launcher (MPICH, srun --mpi=pmi2), else srun's
// task count; 0 when none says.
int launched_size() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS"})
    if (const int size = environment_size(name); size > 0) return size;
  return 0;
}

}  // namespace

bool MpiRun::launched() { return launched_size() > 1; }

#ifdef IVOL_WITH_MPI

bool MpiRun::available() { return true; }

namespace {

// Tags: a slab's data carries its index (modulo the range every MPI has);
// the other messages' tags are in mpi_messages.hpp.
int slab_tag(std::size_t slab) { return 1 + static_cast<int>(slab % 30000); }
// MPI counts are ints: larger slabs go in pieces.
constexpr std::size_t kPieceFloats = std::size_t{1} << 28;

class MpiExchange final : public recon::SlabExchange {
 public:
  MpiExchange() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }

  std::uint64_t agree(std::uint64_t value, const std::string& what) override {
    std::vector<std::uint64_t> values(static_cast<std::size_t>(size_));
    MPI_Allgather(&value, 1, MPI_UINT64_T, values.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD);
    for (int r = 1; r < size_; ++r)
      if (values[r] != values[0])
        throw std::runtime_error("the ranks disagree on " + what + ": rank 0 has " + std::to_string(values[0]) +
                                 ", rank " + std::to_string(r) + " has " + std::to_string(values[r]) +
                                 " (give every rank the same devices, --device-memory and scan)");
    return values[0];
  }

  void broadcast(std::vector<float>& values) override {
    std::uint64_t count = values.size();
    MPI_Bcast(&count, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    values.resize(count);
    for (std::size_t done = 0; done < count; done += kPieceFloats) {
      const int piece = static_cast<int>(std::min<std::size_t>(kPieceFloats, count - done));
      MPI_Bcast(values.data() + done, piece, MPI_FLOAT, 0, MPI_COMM_WORLD);
    }
  }

  void send(std::size_t slab, const std::vector<float>& data) override {
    const std::uint64_t count = data.size();
    MPI_Send(&count, 1, MPI_UINT64_T, 0, slab_tag(slab), MPI_COMM_WORLD);
    for (std::size_t done = 0; done < count; done += kPieceFloats) {
      const int piece = static_cast<int>(std::min<std::size_t>(kPieceFloats, count - done));
      MPI_Send(data.data() + done, piece, MPI_FLOAT, 0, slab_tag(slab), MPI_COMM_WORLD);
    }
    bytes_sent += sizeof count + count * sizeof(float);
    ++slabs_sent;
  }

  void receive(std::size_t slab, int from, std::vector<float>& data) override {
    // Wait for the slab, watching for any rank's failure meanwhile: the
    // failed rank need not be the one this slab comes from.
    mpi::wait_for(from, slab_tag(slab));
    std::uint64_t count = 0;
    MPI_Recv(&count, 1, MPI_UINT64_T, from, slab_tag(slab), MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    data.resize(count);
    for (std::size_t done = 0; done < count; done += kPieceFloats) {
      const int piece = static_cast<int>(std::min<std::size_t>(kPieceFloats, count - done));
      MPI_Recv(data.data() + done, piece, MPI_FLOAT, from, slab_tag(slab), MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
    bytes_received += sizeof count + count * sizeof(float);
  }

  void send_bytes(std::size_t slab, const std::vector<std::uint8_t>& data) override {
    bytes_sent += mpi::send_bytes(data, 0, slab_tag(slab));
    ++slabs_sent;
  }

  void receive_bytes(std::size_t slab, int from, std::vector<std::uint8_t>& data) override {
    mpi::wait_for(from, slab_tag(slab));  // or another rank's failure
    bytes_received += mpi::receive_bytes(data, from, slab_tag(slab));
  }

  void report_failure(const std::string& message) override {
    if (rank_ == 0 || failure_reported) return;
    MPI_Send(message.data(), static_cast<int>(message.size()), MPI_CHAR, 0, mpi::kFailureTag, MPI_COMM_WORLD);
    bytes_sent += message.size();
    failure_reported = true;
  }

  std::uint64_t bytes_sent = 0;
  std::uint64_t bytes_received = 0;
  std::uint64_t slabs_sent = 0;
  bool failure_reported = false;

 private:
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace

struct MpiRun::Impl {
  std::shared_ptr<MpiExchange> exchange;
  std::shared_ptr<MpiBlockFarm> farm;
};

MpiRun::MpiRun() : impl_(std::make_unique<Impl>()) {
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  if (provided < MPI_THREAD_FUNNELED) {
    MPI_Finalize();
    throw Error(ErrorClass::InvalidArgument, "the MPI library does not allow threads (MPI_THREAD_FUNNELED)");
  }
  impl_->exchange = std::make_shared<MpiExchange>();
  impl_->farm = std::make_shared<MpiBlockFarm>(impl_->exchange);
  if (size() != launched_size()) {
    // Each of the launcher's processes would write the whole volume.
    const std::string message = "started as " + std::to_string(launched_size()) + " processes, but MPI sees " +
                                std::to_string(size()) + " (with srun, give --mpi=pmix, or use mpirun)";
    MPI_Finalize();
    throw Error(ErrorClass::InvalidArgument, message);
  }
}

MpiRun::~MpiRun() { MPI_Finalize(); }

int MpiRun::rank() const { return impl_->exchange->rank(); }
int MpiRun::size() const { return impl_->exchange->size(); }
std::shared_ptr<recon::SlabExchange> MpiRun::exchange() const { return impl_->exchange; }
// IVOL_MPI_COMPRESS_ON_RANK0=1 compresses on rank 0 alone, as before the
// farm: for measuring what the farm changes (bench/RESULTS.md).
std::shared_ptr<BlockEncoder> MpiRun::block_encoder() const {
  const char* rank0_only = std::getenv("IVOL_MPI_COMPRESS_ON_RANK0");
  if (rank0_only != nullptr && std::string(rank0_only) == "1") return nullptr;
  return impl_->farm;
}
void MpiRun::every_slab_received() { impl_->farm->every_slab_received(); }
void MpiRun::end_compression() { impl_->farm->release(); }
void MpiRun::serve_compression() { impl_->farm->work(); }

std::vector<RankStats> MpiRun::gather(RankStats mine) {
  const CompressionStats& compression = impl_->farm->stats();
  mine.block_bytes_sent = compression.bytes_sent;
  mine.block_bytes_received = compression.bytes_received;
  mine.slab_bytes_sent = impl_->exchange->bytes_sent;
  mine.slab_bytes_received = impl_->exchange->bytes_received;
  mine.bytes_sent = impl_->exchange->bytes_sent + compression.bytes_sent;
  mine.bytes_received = impl_->exchange->bytes_received + compression.bytes_received;
  mine.slabs_sent = impl_->exchange->slabs_sent;
  mine.blocks_compressed = compression.blocks;
  mine.compression_input_bytes = compression.input_bytes;
  mine.compression_output_bytes = compression.output_bytes;
  mine.compression_seconds = compression.seconds;
  static_assert(sizeof(RankStats) % 8 == 0, "RankStats travels as bytes");
  std::vector<RankStats> all(rank() == 0 ? static_cast<std::size_t>(size()) : 0);
  MPI_Gather(&mine, sizeof mine, MPI_BYTE, all.data(), sizeof mine, MPI_BYTE, 0, MPI_COMM_WORLD);
  return all;
}

void MpiRun::fail(const std::exception& what) {
  const auto* error = dynamic_cast<const Error*>(&what);
  const std::string kind = error != nullptr ? std::string(" (") + error_class_name(error->error_class()) + ")" : "";
  if (rank() != 0 && impl_->exchange->failure_reported) {
    // Rank 0 prints it and ends the run once its output is gone; end it
    // here only if rank 0 never does.
    std::this_thread::sleep_for(std::chrono::seconds(60));
  } else {
    // One write, so that the lines of ranks failing at once do not interleave.
    const std::string who = rank() == 0 ? "" : "rank " + std::to_string(rank()) + ": ";
    const std::string line = "ivol recon: " + who + "error" + kind + ": " + what.what() + "\n";
    std::cerr.write(line.data(), static_cast<std::streamsize>(line.size()));
    std::cerr.flush();
  }
  MPI_Abort(MPI_COMM_WORLD, kExitFailure);  // mpirun exits with it, as one process would
  std::_Exit(kExitFailure);
}

#else  // built without MPI

bool MpiRun::available() { return false; }

struct MpiRun::Impl {};

MpiRun::MpiRun() {
  throw Error(ErrorClass::InvalidArgument,
              "started by mpirun, but this ivol was built without MPI (IVOL_WITH_MPI=OFF): every copy would "
              "reconstruct and write the whole volume; install libopenmpi-dev and rebuild");
}
MpiRun::~MpiRun() = default;
int MpiRun::rank() const { return 0; }
int MpiRun::size() const { return 1; }
std::shared_ptr<recon::SlabExchange> MpiRun::exchange() const { return nullptr; }
std::shared_ptr<BlockEncoder> MpiRun::block_encoder() const { return nullptr; }
void MpiRun::every_slab_received() {}
void MpiRun::end_compression() {}
void MpiRun::serve_compression() {}
std::vector<RankStats> MpiRun::gather(RankStats mine) { return {mine}; }
void MpiRun::fail(const std::exception& what) {
  std::cerr << "ivol recon: error: " << what.what() << std::endl;
  std::_Exit(kExitFailure);
}

#endif


}  // namespace ivol::cli
