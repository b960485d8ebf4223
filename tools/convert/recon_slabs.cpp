#include "recon_slabs.hpp"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace ivol::convert {

DenseVolume float_volume_of(const recon::VolumeGrid& grid) {
  DenseVolume shape;
  shape.dims = Dims{grid.size[0], grid.size[1], grid.size[2]};
  shape.type = SampleType::Float32;
  shape.has_geometry = true;
  shape.voxel_size = {grid.voxel_size[0], grid.voxel_size[1], grid.voxel_size[2]};
  shape.origin = {grid.origin[0], grid.origin[1], grid.origin[2]};
  shape.unit = "mm";
  return shape;
}

namespace {

void add(recon::FdkTimings& into, const recon::FdkTimings& t) {
  into.setup += t.setup;
  into.reading += t.reading;
  into.filtering += t.filtering;
  into.backprojection += t.backprojection;
  into.transfer += t.transfer;
  into.delivery += t.delivery;
  into.total += t.total;
}

}  // namespace

ReconstructionSlabs::ReconstructionSlabs(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid)
    : reconstructor_(reconstructor), grid_(grid) {
  shape_ = float_volume_of(grid);
}

void ReconstructionSlabs::read(std::uint32_t z0, std::uint32_t count, void* out) {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t slice = std::size_t{grid_.size[0]} * grid_.size[1];
  float* target = static_cast<float*>(out);
  const std::uint32_t cached = static_cast<std::uint32_t>(cache_.size() / slice);
  std::uint32_t first = z0;
  // Slices at the start of this read that the previous one already made.
  if (z0 >= cache_first_ && z0 < cache_first_ + cached) {
    const std::uint32_t reuse = std::min(count, cache_first_ + cached - z0);
    std::memcpy(target, cache_.data() + (z0 - cache_first_) * slice, reuse * slice * sizeof(float));
    first = z0 + reuse;
  }
  if (first < z0 + count) {
    const recon::FdkReport report = reconstructor_.reconstruct(
        grid_,
        [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
          std::memcpy(target + (k0 - z0) * slice, data, (k1 - k0) * slice * sizeof(float));
        },
        first, z0 + count);
    add(timings_, report.timings);
    voxel_updates_ += report.voxel_updates;
    slices_reconstructed_ += z0 + count - first;
  }
  cache_first_ = z0;
  cache_.assign(target, target + count * slice);
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double ReconstructionSlabs::gups() const {
  return timings_.backprojection > 0 ? static_cast<double>(voxel_updates_) / timings_.backprojection * 1e-9 : 0.0;
}

}  // namespace ivol::convert

namespace ivol::convert {
namespace {

// Thrown to the writer when the reconstruction failed: the reconstruction's
// own error is the one reported.
struct ReconstructionStopped : std::runtime_error {
  ReconstructionStopped() : std::runtime_error("the reconstruction stopped") {}
};
// Thrown to the reconstruction when the writer failed: the writer's own error
// is the one reported.
struct WriterStopped : std::runtime_error {
  WriterStopped() : std::runtime_error("the writer stopped") {}
};

// Slices handed from the reconstruction (push, in z order) to a reader that
// asks for them in z order, re-reading at most the slices of its previous
// read (a keep mask's margin). The reconstruction pushes only when the
// reader wants slices it does not have, so the buffer holds the reader's
// last read and at most one slab more.
class SlabHandoff final : public SlabReader {
 public:
  explicit SlabHandoff(const recon::VolumeGrid& grid)
      : slice_(std::size_t{grid.size[0]} * grid.size[1]), depth_(grid.size[2]) {
    shape_ = float_volume_of(grid);
  }

  void push(std::uint32_t k_begin, std::uint32_t k_end, const float* data) {
    std::unique_lock<std::mutex> lock(mutex_);
    wanted_.wait(lock, [&] { return reader_failed_ || end_ < wanted_end_; });
    if (reader_failed_) throw WriterStopped();
    if (k_begin != end_) throw std::logic_error("slices arrived out of order");
    buffer_.insert(buffer_.end(), data, data + (k_end - k_begin) * slice_);
    end_ = k_end;
    arrived_.notify_all();
  }
  void stop(bool reader) {
    std::lock_guard<std::mutex> lock(mutex_);
    (reader ? reader_failed_ : producer_failed_) = true;
    arrived_.notify_all();
    wanted_.notify_all();
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    if (z0 < first_ || z0 + count > depth_)
      throw std::logic_error("a streamed reconstruction is read once, in z order");
    wanted_end_ = std::max(wanted_end_, z0 + count);
    wanted_.notify_all();
    arrived_.wait(lock, [&] { return producer_failed_ || end_ >= z0 + count; });
    if (producer_failed_) throw ReconstructionStopped();
    waiting_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    // What lies before this read is never read again.
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>((z0 - first_) * slice_));
    first_ = z0;
    std::memcpy(out, buffer_.data(), count * slice_ * sizeof(float));
  }

  double waiting_seconds() const { return waiting_; }

 private:
  std::size_t slice_;
  std::uint32_t depth_;
  std::mutex mutex_;
  std::condition_variable arrived_, wanted_;
  std::vector<float> buffer_;  // slices [first_, end_)
  std::uint32_t first_ = 0;
  std::uint32_t end_ = 0;
  std::uint32_t wanted_end_ = 0;
  bool producer_failed_ = false;
  bool reader_failed_ = false;
  double waiting_ = 0.0;
};

}  // namespace

StreamedReconstruction reconstruct_to_ivol(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                           const std::string& path, const ImportOptions& options, bool write,
                                           WriterService* service) {
  StreamedReconstruction result;
  if (!write) {
    result.fdk = reconstructor.reconstruct(grid, [](std::uint32_t, std::uint32_t, const float*) {
      throw std::logic_error("only rank 0 receives the reconstructed slabs");
    });
    return result;
  }
  SlabHandoff handoff(grid);
  std::exception_ptr writer_error;
  std::thread writer([&] {
    try {
      result.written = import_to_ivol(handoff, path, options);
    } catch (const ReconstructionStopped&) {
    } catch (...) {
      writer_error = std::current_exception();
      handoff.stop(true);
    }
    if (service) service->close();
  });
  try {
    result.fdk = reconstructor.reconstruct(
        grid, [&](std::uint32_t k0, std::uint32_t k1, const float* data) { handoff.push(k0, k1, data); });
    if (service) service->serve();
  } catch (...) {
    const std::exception_ptr error = std::current_exception();
    handoff.stop(false);
    if (service) service->close();  // a writer already waiting on it fails too
    writer.join();                  // the writer removes its temporary file as it unwinds
    std::rethrow_exception(writer_error ? writer_error : error);
  }
  writer.join();
  if (writer_error) std::rethrow_exception(writer_error);
  result.writer_waiting = handoff.waiting_seconds();
  return result;
}

}  // namespace ivol::convert
