#include "recon_built_slabs.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "bricked_import.hpp"
#include "ivol/octree_slab_builder.hpp"
#include "ivol/streaming_writer.hpp"
#include "recon_built_layers.hpp"
#include "recon_slabs.hpp"

namespace ivol::convert {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// A later slab's report into the first's (which says the devices and plan).
void add_fdk_report(recon::FdkReport& into, const recon::FdkReport& report) {
  recon::FdkTimings& t = into.timings;
  t.setup += report.timings.setup;
  t.reading += report.timings.reading;
  t.filtering += report.timings.filtering;
  t.backprojection += report.timings.backprojection;
  t.transfer += report.timings.transfer;
  t.delivery += report.timings.delivery;
  t.total += report.timings.total;
  into.slab_count += report.slab_count;
  into.voxel_updates += report.voxel_updates;
  into.rows_filtered += report.rows_filtered;
  into.filtered_rows_host_bytes = std::max(into.filtered_rows_host_bytes, report.filtered_rows_host_bytes);
  into.filtered_rows_disk_bytes = std::max(into.filtered_rows_disk_bytes, report.filtered_rows_disk_bytes);
}

}  // namespace

void reconstruct_slices(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid, std::uint32_t lo,
                        std::uint32_t hi, std::vector<float>& values, DistributedBuild& result) {
  const std::size_t slice = std::size_t{grid.size[0]} * grid.size[1];
  values.resize((hi - lo) * slice);
  const auto reconstructing = std::chrono::steady_clock::now();
  const recon::FdkReport fdk = reconstructor.reconstruct(
      grid,
      [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
        std::memcpy(values.data() + (k0 - lo) * slice, data, (k1 - k0) * slice * sizeof(float));
      },
      lo, hi);
  if (result.slabs_built == 0)
    result.fdk = fdk;
  else
    add_fdk_report(result.fdk, fdk);
  result.reconstruction_seconds += seconds_since(reconstructing);
}

int rank_told_to_fail_building() {
  const char* value = std::getenv("IVOL_TEST_FAIL_BUILD_RANK");
  return value != nullptr ? std::atoi(value) : -1;
}

std::uint32_t distributed_slab_slices(const Dims& dims, const StreamingOptions& options, int ranks,
                                      std::uint32_t most_slices, unsigned slabs_per_rank) {
  std::uint32_t slab = OctreeSlabBuilder(dims, options).slab_slices();
  const auto slabs = [&](std::uint32_t slices) { return (dims[2] + slices - 1) / slices; };
  while (slab > 1 && slabs(slab) < static_cast<std::uint64_t>(ranks) * slabs_per_rank) slab /= 2;
  while (most_slices > 0 && slab > most_slices) slab /= 2;
  return slab;
}

DistributedBuild reconstruct_distributed(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                         const std::string& path, const ImportOptions& options,
                                         recon::SlabExchange& exchange, std::uint32_t most_slab_slices,
                                         const std::function<void()>& every_slab_received) {
  const auto start = std::chrono::steady_clock::now();
  const DenseVolume shape = float_volume_of(grid);
  // Every rank must make the same choice (they could differ only in
  // --memory): a bricked grid's layers or the octree writer's slabs.
  ImportReport choice;
  const ValueEncoding encoding = import_streaming_options(shape, options, choice).build.encoding;
  if (exchange.agree(choose_bricked(shape, options, encoding, choice) ? 1 : 0,
                     "the output's structure (1: a bricked grid, 0: an octree)") == 1)
    return reconstruct_distributed_bricked(reconstructor, grid, path, options, exchange, most_slab_slices,
                                           every_slab_received);
  DistributedBuild result;
  ImportReport& report = result.written;
  report.structure_reason = choice.structure_reason;  // finish_import records it, as import_to_ivol's does
  StreamingOptions streaming = import_streaming_options(shape, options, report);
  streaming.slab_slices = static_cast<std::uint32_t>(
      exchange.agree(distributed_slab_slices(shape.dims, streaming, exchange.size(), most_slab_slices),
                     "the writer's slab thickness in slices"));
  const OctreeSlabBuilder builder(shape.dims, streaming);
  report.slab_slices = builder.slab_slices();
  if (options.keep && options.keep->otsu)
    throw std::logic_error("a distributed keep rule needs its threshold given (Otsu's on the preview)");
  if (options.keep) report.threshold = options.keep->threshold;
  const unsigned margin = options.keep ? options.keep->margin : 0;
  const std::uint32_t depth = shape.dims[2];
  const std::size_t slice = std::size_t{shape.dims[0]} * shape.dims[1];
  const std::uint32_t slab_count = builder.slab_count();
  const bool injected_failure = rank_told_to_fail_building() == exchange.rank();

  // One of this rank's slabs: reconstructed with its margin, its keep mask,
  // its subtrees.
  std::vector<float> values;
  auto build_mine = [&](std::uint32_t k) {
    const std::uint32_t z0 = builder.slab_first(k);
    const std::uint32_t n = builder.slab_size(k);
    const std::uint32_t lo = z0 >= margin ? z0 - margin : 0;
    const std::uint32_t hi = std::min(depth, z0 + n + margin);
    reconstruct_slices(reconstructor, grid, lo, hi, values, result);
    const auto building = std::chrono::steady_clock::now();
    std::vector<std::uint8_t> keep;
    if (options.keep) keep = slab_keep_mask(values.data(), shape.dims, lo, hi, z0, n, report.threshold, margin);
    if (injected_failure)
      throw std::runtime_error("building the subtrees of slab " + std::to_string(k) +
                               ": failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
    BuiltSlab built = builder.build(k, values.data() + (z0 - lo) * slice, options.keep ? keep.data() : nullptr);
    result.build_seconds += seconds_since(building);
    ++result.slabs_built;
    result.slices_built += n;
    return built;
  };

  if (exchange.rank() != 0) {
    try {
      for (std::uint32_t k = 0; k < slab_count; ++k)
        if (exchange.owner(k, slab_count) == exchange.rank()) exchange.send_bytes(k, build_mine(k).bytes);
    } catch (const std::exception& error) {
      exchange.report_failure(error.what());  // rank 0 is waiting for this rank's slabs
      throw;
    }
    return result;
  }

  StreamingOctreeWriter writer(path, shape.dims, streaming);
  for (std::uint32_t k = 0; k < slab_count; ++k) {
    const int from = exchange.owner(k, slab_count);
    BuiltSlab built;
    if (from == 0) {
      built = build_mine(k);
    } else {
      const auto waiting = std::chrono::steady_clock::now();
      exchange.receive_bytes(k, from, built.bytes);
      result.waiting_seconds += seconds_since(waiting);
    }
    const auto adding = std::chrono::steady_clock::now();
    writer.add_built_slab(built);
    result.writing_seconds += seconds_since(adding);
    if (options.progress) options.progress(builder.slab_first(k) + builder.slab_size(k), depth);
  }
  every_slab_received();
  const auto finishing = std::chrono::steady_clock::now();
  finish_import(writer, shape, options, report);
  result.writing_seconds += seconds_since(finishing);
  report.seconds = seconds_since(start);
  return result;
}

}  // namespace ivol::convert
