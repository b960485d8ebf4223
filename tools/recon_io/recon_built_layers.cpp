#include "recon_built_layers.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "bricked_import.hpp"
#include "recon_slabs.hpp"

namespace ivol::convert {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

struct LayerSlab {
  std::uint32_t z0, count;
};

// The slabs in z order: slabs of `slices` whole layers (a multiple of
// `layer`), or each layer cut into slabs of `slices` (its last slab thinner
// where the layer is).
std::vector<LayerSlab> layer_slabs(std::uint32_t depth, std::uint32_t layer, std::uint32_t slices) {
  std::vector<LayerSlab> slabs;
  if (slices > layer) {
    for (std::uint32_t z = 0; z < depth; z += slices) slabs.push_back({z, std::min(slices, depth - z)});
    return slabs;
  }
  for (std::uint32_t l0 = 0; l0 < depth; l0 += layer) {
    const std::uint32_t end = std::min(depth, l0 + layer);
    for (std::uint32_t z = l0; z < end; z += slices) slabs.push_back({z, std::min(slices, end - z)});
  }
  return slabs;
}

// A slab's stored values, then what rounding them changed, as bytes: the
// ranks run the same binary, so LossTally travels as it is in memory.
template <class T>
std::vector<std::uint8_t> pack(const T* stored, std::uint64_t count, const LossTally& loss) {
  std::vector<std::uint8_t> bytes(count * sizeof(T) + sizeof loss);
  std::memcpy(bytes.data(), stored, count * sizeof(T));
  std::memcpy(bytes.data() + count * sizeof(T), &loss, sizeof loss);
  return bytes;
}

}  // namespace

std::uint32_t distributed_layer_slab_slices(std::uint32_t layer_slices, std::uint32_t depth, int ranks,
                                            std::uint32_t most_slices) {
  const std::uint32_t layer = std::max(layer_slices, 1u);
  // Whole layers, as many as `most_slices` holds (a power of two of them):
  // thick slabs cost the FDK less per voxel.
  std::uint32_t slab = layer;
  while (most_slices > 0 && std::uint64_t{slab} * 2 <= most_slices && slab < depth) slab *= 2;
  const auto slabs = [&](std::uint32_t slices) { return layer_slabs(depth, layer, slices).size(); };
  while (slab > 1 && slabs(slab) < static_cast<std::size_t>(ranks)) slab = slab > layer ? slab / 2 : (slab + 1) / 2;
  while (most_slices > 0 && slab > most_slices) slab = (slab + 1) / 2;
  return slab;
}

namespace {

// reconstruct_distributed_bricked's work, T the stored values' type
// (with_stored_type).
template <class T>
DistributedBuild distributed_bricked(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                     const std::string& path, const ImportOptions& options,
                                     recon::SlabExchange& exchange, std::uint32_t most_slab_slices,
                                     const std::function<void()>& every_slab_received,
                                     std::chrono::steady_clock::time_point start, const DenseVolume& shape,
                                     const StreamingOptions& streaming, DistributedBuild result) {
  ImportReport& report = result.written;
  const std::uint32_t depth = shape.dims[2];
  const std::uint32_t layer = std::min<std::uint32_t>(depth, 1u << options.brick_log2);
  // Within the layer's budget, as one process reads it (bricked_read_slices).
  const std::uint32_t read = std::max(1u, bricked_read_slices(shape, options, streaming.build.encoding));
  const std::uint32_t most = most_slab_slices ? std::min(most_slab_slices, read) : read;
  const auto slab_slices =
      static_cast<std::uint32_t>(exchange.agree(distributed_layer_slab_slices(layer, depth, exchange.size(), most),
                                                "the slab thickness in slices (a bricked grid's layers)"));
  report.slab_slices = slab_slices;
  const std::vector<LayerSlab> slabs = layer_slabs(depth, layer, slab_slices);
  const std::size_t slice = std::size_t{shape.dims[0]} * shape.dims[1];
  const bool injected_failure = rank_told_to_fail_building() == exchange.rank();

  // One of this rank's slabs: reconstructed, then as stored values.
  std::vector<float> values, scratch;
  auto build_mine = [&](std::size_t k, T* stored, LossTally& loss) {
    const LayerSlab& s = slabs[k];
    reconstruct_slices(reconstructor, grid, s.z0, s.z0 + s.count, values, result);
    const auto building = std::chrono::steady_clock::now();
    if (injected_failure)
      throw std::runtime_error("storing the values of slab " + std::to_string(k) +
                               ": failure injected (IVOL_TEST_FAIL_BUILD_RANK)");
    samples_to_stored(shape, streaming.build, reinterpret_cast<const std::uint8_t*>(values.data()),
                      std::uint64_t{s.count} * slice, scratch, stored, loss);
    result.build_seconds += seconds_since(building);
    ++result.slabs_built;
    result.slices_built += s.count;
  };

  if (exchange.rank() != 0) {
    try {
      std::vector<T> stored;
      for (std::size_t k = 0; k < slabs.size(); ++k) {
        if (exchange.owner(k, slabs.size()) != exchange.rank()) continue;
        stored.resize(std::size_t{slabs[k].count} * slice);
        LossTally loss;
        build_mine(k, stored.data(), loss);
        exchange.send_bytes(k, pack(stored.data(), stored.size(), loss));
      }
    } catch (const std::exception& error) {
      exchange.report_failure(error.what());  // rank 0 is waiting for this rank's slabs
      throw;
    }
    return result;
  }

  BrickedImport writer(shape, path, options, streaming);
  // Slabs of whole layers, or a layer gathered from its slabs; `base` is the
  // first slice the buffer holds.
  std::vector<T> layer_values(std::size_t{std::max(layer, slab_slices)} * slice);
  std::uint32_t base = 0;
  std::vector<std::uint8_t> received;
  LossTally loss;
  for (std::size_t k = 0; k < slabs.size(); ++k) {
    const LayerSlab& s = slabs[k];
    if (s.z0 == writer.next_layer_first()) base = s.z0;
    T* into = layer_values.data() + std::size_t{s.z0 - base} * slice;
    const std::size_t count = std::size_t{s.count} * slice;
    const int from = exchange.owner(k, slabs.size());
    if (from == 0) {
      LossTally mine;
      build_mine(k, into, mine);
      loss.merge(mine);
    } else {
      const auto waiting = std::chrono::steady_clock::now();
      exchange.receive_bytes(k, from, received);
      result.waiting_seconds += seconds_since(waiting);
      LossTally theirs;
      if (received.size() != count * sizeof(T) + sizeof theirs)
        throw std::runtime_error("rank " + std::to_string(from) + " sent " + std::to_string(received.size()) +
                                 " bytes for slab " + std::to_string(k) + ", not " +
                                 std::to_string(count * sizeof(T) + sizeof theirs));
      std::memcpy(into, received.data(), count * sizeof(T));
      std::memcpy(&theirs, received.data() + count * sizeof(T), sizeof theirs);
      loss.merge(theirs);
    }
    // Every layer the slabs have completed.
    while (writer.next_layer_count() > 0 && writer.next_layer_first() + writer.next_layer_count() <= s.z0 + s.count) {
      const auto adding = std::chrono::steady_clock::now();
      writer.add_layer(layer_values.data() + std::size_t{writer.next_layer_first() - base} * slice);
      result.writing_seconds += seconds_since(adding);
    }
    if (options.progress) options.progress(s.z0 + s.count, depth);
  }
  every_slab_received();
  const auto finishing = std::chrono::steady_clock::now();
  writer.finish(loss, report);
  result.writing_seconds += seconds_since(finishing);
  report.seconds = seconds_since(start);
  return result;
}

}  // namespace

DistributedBuild reconstruct_distributed_bricked(recon::FdkReconstructor& reconstructor, const recon::VolumeGrid& grid,
                                                 const std::string& path, const ImportOptions& options,
                                                 recon::SlabExchange& exchange, std::uint32_t most_slab_slices,
                                                 const std::function<void()>& every_slab_received) {
  const auto start = std::chrono::steady_clock::now();
  const DenseVolume shape = float_volume_of(grid);
  DistributedBuild result;
  const StreamingOptions streaming = import_streaming_options(shape, options, result.written);
  if (!choose_bricked(shape, options, streaming.build.encoding, result.written))
    throw std::logic_error("a distributed bricked grid needs a volume that import_to_ivol writes as one");
  return with_stored_type(streaming.build.encoding, [&](auto t) {
    return distributed_bricked<decltype(t)>(reconstructor, grid, path, options, exchange, most_slab_slices,
                                            every_slab_received, start, shape, streaming, std::move(result));
  });
}

}  // namespace ivol::convert
