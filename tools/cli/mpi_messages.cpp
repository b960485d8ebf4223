#include "mpi_messages.hpp"

#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>

namespace ivol::cli::mpi {
namespace {

constexpr std::size_t kPieceBytes = std::size_t{1} << 30;

[[noreturn]] void throw_failure() {
  MPI_Status status;
  MPI_Probe(MPI_ANY_SOURCE, kFailureTag, MPI_COMM_WORLD, &status);
  int length = 0;
  MPI_Get_count(&status, MPI_CHAR, &length);
  std::string message(static_cast<std::size_t>(length), '\0');
  MPI_Recv(message.data(), length, MPI_CHAR, status.MPI_SOURCE, kFailureTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  throw std::runtime_error("rank " + std::to_string(status.MPI_SOURCE) + ": " + message);
}

}  // namespace

void wait_for(int from, int tag) {
  for (;;) {
    int arrived = 0;
    MPI_Iprobe(MPI_ANY_SOURCE, kFailureTag, MPI_COMM_WORLD, &arrived, MPI_STATUS_IGNORE);
    if (arrived) throw_failure();
    MPI_Iprobe(from, tag, MPI_COMM_WORLD, &arrived, MPI_STATUS_IGNORE);
    if (arrived) return;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
}

std::uint64_t send_bytes(const std::vector<std::uint8_t>& bytes, int to, int tag) {
  const std::uint64_t count = bytes.size();
  MPI_Send(&count, 1, MPI_UINT64_T, to, tag, MPI_COMM_WORLD);
  for (std::size_t done = 0; done < count; done += kPieceBytes) {
    const int piece = static_cast<int>(std::min<std::size_t>(kPieceBytes, count - done));
    MPI_Send(bytes.data() + done, piece, MPI_BYTE, to, tag, MPI_COMM_WORLD);
  }
  return sizeof count + count;
}

std::uint64_t receive_bytes(std::vector<std::uint8_t>& bytes, int from, int tag) {
  std::uint64_t count = 0;
  MPI_Recv(&count, 1, MPI_UINT64_T, from, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  bytes.resize(count);
  for (std::size_t done = 0; done < count; done += kPieceBytes) {
    const int piece = static_cast<int>(std::min<std::size_t>(kPieceBytes, count - done));
    MPI_Recv(bytes.data() + done, piece, MPI_BYTE, from, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  }
  return sizeof count + count;
}

}  // namespace ivol::cli::mpi
