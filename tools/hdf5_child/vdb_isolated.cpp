// The OpenVDB volume reader as the converters use it: read_vdb (vdb_io.cpp)
// runs in a child process, and this proxy forwards the shape and slabs from
// it (isolated_worker.hpp says why; libopenvdb allocates what a damaged
// file's blosc block headers claim, tests/fuzz/regressions/vdb/vdb-blosc-*).
#include <cstdint>
#include <memory>
#include <utility>

#include "isolated_worker.hpp"
#include "ivol/error.hpp"
#include "sizes.hpp"
#include "vdb_io.hpp"

namespace ivol::convert {
namespace {

constexpr const char* kLibrary = "libopenvdb";
constexpr char kOpen = 'o';
constexpr char kRead = 'r';
constexpr const char* kVolumeWorker = "vdb-volume";

// The parameters of a volume worker: the file, the grid (empty: the first
// float grid), the budget read_vdb weighs the dense box against.
std::string volume_parameters(const std::string& path, const std::string& grid_name, std::uint64_t memory_bytes) {
  WireWriter out;
  out.put_string(path).put_string(grid_name).put(memory_bytes);
  return std::move(out.bytes());
}

WorkerHandler volume_handler(std::string_view parameters) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const std::string grid_name = in.get_string();
  const auto memory_bytes = in.get<std::uint64_t>();
  auto reader = std::make_shared<std::unique_ptr<SlabReader>>();
  return [path, grid_name, memory_bytes, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      VdbSourceInfo source;
      *reader = open_vdb_slabs_in_process(path, grid_name, &source, memory_bytes);
      const DenseVolume& shape = (*reader)->shape();
      WireWriter reply;
      reply.put(shape.dims).put(shape.type).put(shape.voxel_size).put(shape.origin).put_string(shape.unit);
      reply.put(shape.has_geometry).put_string(shape.quantity).put_string(shape.value_unit);
      reply.put_string(shape.provenance).put_string(shape.voxel_size_from).put_string(shape.origin_from);
      reply.put_string(shape.unit_from).put_string(shape.quantity_from);
      reply.put<std::uint64_t>(shape.notes.size());
      for (const std::string& note : shape.notes) reply.put_string(note);
      reply.put_string(source.grid_name).put(source.background).put(source.was_half);
      out.reply = std::move(reply.bytes());
      return;
    }
    if (operation != kRead || !*reader)
      throw Error(ErrorClass::InvalidArgument,
                  "isolated OpenVDB reader: unexpected request " + std::string(1, operation));
    const auto z0 = in.get<std::uint32_t>();
    const auto count = in.get<std::uint32_t>();
    const DenseVolume& shape = (*reader)->shape();
    out.bulk.resize(std::size_t{count} * shape.dims[0] * shape.dims[1] * sample_size(shape.type));
    (*reader)->read(z0, count, out.bulk.data());
  };
}

class IsolatedVdbSlabReader final : public SlabReader {
 public:
  IsolatedVdbSlabReader(const std::string& path, const std::string& grid_name, VdbSourceInfo* source,
                        std::uint64_t memory_bytes)
      : worker_(path, kLibrary, kVolumeWorker, volume_parameters(path, grid_name, memory_budget(memory_bytes)),
                // The child holds the grid and its dense copy, each within
                // the budget (a leaf voxel costs less than the dense box's
                // 6 bytes), so twice the budget; the slab replies come on top.
                memory_budget(memory_bytes) > UINT64_MAX / 2 ? UINT64_MAX : 2 * memory_budget(memory_bytes)) {
    WireWriter request;
    request.put(kOpen);
    WireReader reply(worker_.call(request.bytes(), grid_name.empty() ? std::string("opening the first float grid")
                                                                     : "opening grid '" + grid_name + "'"));
    shape_.dims = reply.get<Dims>();
    shape_.type = reply.get<SampleType>();
    shape_.voxel_size = reply.get<std::array<double, 3>>();
    shape_.origin = reply.get<std::array<double, 3>>();
    shape_.unit = reply.get_string();
    shape_.has_geometry = reply.get<bool>();
    shape_.quantity = reply.get_string();
    shape_.value_unit = reply.get_string();
    shape_.provenance = reply.get_string();
    shape_.voxel_size_from = reply.get_string();
    shape_.origin_from = reply.get_string();
    shape_.unit_from = reply.get_string();
    shape_.quantity_from = reply.get_string();
    shape_.notes.resize(static_cast<std::size_t>(reply.get<std::uint64_t>()));
    for (std::string& note : shape_.notes) note = reply.get_string();
    VdbSourceInfo info;
    info.grid_name = reply.get_string();
    info.background = reply.get<float>();
    info.was_half = reply.get<bool>();
    grid_ = info.grid_name;
    if (source) *source = std::move(info);
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    WireWriter request;
    request.put(kRead).put(z0).put(count);
    const std::size_t bytes = std::size_t{count} * shape_.dims[0] * shape_.dims[1] * sample_size(shape_.type);
    worker_.call(
        request.bytes(),
        "reading slices " + std::to_string(z0) + " .. " + std::to_string(z0 + count) + " of grid '" + grid_ + "'", out,
        bytes);
  }

 private:
  IsolatedWorker worker_;
  std::string grid_;
};

const WorkerKind volume_worker(kVolumeWorker, volume_handler);

}  // namespace

std::unique_ptr<SlabReader> open_vdb_slabs(const std::string& path, const std::string& grid_name, VdbSourceInfo* source,
                                           std::uint64_t memory_bytes) {
  return std::make_unique<IsolatedVdbSlabReader>(path, grid_name, source, memory_bytes);
}

}  // namespace ivol::convert
