// The OpenVDB volume reader as the converters use it: read_vdb (vdb_io.cpp)
// runs in a child process, and this proxy forwards the shape and slabs from
// it (isolated_worker.hpp says why; libopenvdb allocates what a damaged
// file's blosc block headers claim, tests/fuzz/regressions/vdb/vdb-blosc-*).
#include <cstdint>
#include <memory>
#include <utility>

#include "isolated_slabs.hpp"
#include "isolated_worker.hpp"
#include "ivol/error.hpp"
#include "sizes.hpp"
#include "vdb_io.hpp"

namespace ivol::convert {
namespace {

constexpr const char* kLibrary = "libopenvdb";
constexpr const char* kVolumeWorker = "vdb-volume";

// The child's side: read_vdb within the budget, and what the parent's side
// reports of the grid.
std::unique_ptr<SlabReader> open_grid_in_child(const std::string& path, const std::string& grid_name,
                                               std::uint64_t memory_bytes, WireWriter& info) {
  VdbSourceInfo source;
  auto reader = open_vdb_slabs_in_process(path, grid_name, &source, memory_bytes);
  info.put_string(source.grid_name).put(source.background).put(source.was_half);
  return reader;
}

WorkerHandler volume_handler(std::string_view parameters) {
  return slab_worker_handler(parameters, open_grid_in_child, "isolated OpenVDB reader");
}

const WorkerKind volume_worker(kVolumeWorker, volume_handler);

}  // namespace

std::unique_ptr<SlabReader> open_vdb_slabs(const std::string& path, const std::string& grid_name, VdbSourceInfo* source,
                                           std::uint64_t memory_bytes) {
  SlabWorkerSpec spec;
  spec.path = path;
  spec.name = grid_name;
  spec.reader_memory = memory_budget(memory_bytes);
  // The child holds the grid and its dense copy, each within the budget (a
  // leaf voxel costs less than the dense box's 6 bytes), so twice the
  // budget; the slab replies come on top.
  spec.child_memory = spec.reader_memory > UINT64_MAX / 2 ? UINT64_MAX : 2 * spec.reader_memory;
  spec.library = kLibrary;
  spec.kind = kVolumeWorker;
  spec.opening = grid_name.empty() ? std::string("opening the first float grid") : "opening grid '" + grid_name + "'";
  return std::make_unique<IsolatedSlabReader>(spec, [source](WireReader& reply) {
    VdbSourceInfo info;
    info.grid_name = reply.get_string();
    info.background = reply.get<float>();
    info.was_half = reply.get<bool>();
    const std::string grid = "grid '" + info.grid_name + "'";
    if (source) *source = std::move(info);
    return grid;
  });
}

}  // namespace ivol::convert
