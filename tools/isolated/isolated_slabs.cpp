#include "isolated_slabs.hpp"

#include <utility>

#include "ivol/error.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

constexpr char kOpen = 'o';
constexpr char kRead = 'r';
constexpr char kReadRows = 'b';

void put_shape(WireWriter& out, const DenseVolume& shape) {
  out.put(shape.dims).put(shape.type).put(shape.voxel_size).put(shape.origin).put_string(shape.unit);
  out.put(shape.has_geometry).put_string(shape.quantity).put_string(shape.value_unit);
  out.put_string(shape.provenance).put_string(shape.voxel_size_from).put_string(shape.origin_from);
  out.put_string(shape.unit_from).put_string(shape.quantity_from);
  out.put<std::uint64_t>(shape.notes.size());
  for (const std::string& note : shape.notes) out.put_string(note);
}

// Not inlined: GCC 12 then takes the reply's short-string buffer for
// uninitialised (-Wmaybe-uninitialized, a false alarm).
[[gnu::noinline]] void get_shape(WireReader& in, DenseVolume& shape) {
  shape.dims = in.get<Dims>();
  shape.type = in.get<SampleType>();
  shape.voxel_size = in.get<std::array<double, 3>>();
  shape.origin = in.get<std::array<double, 3>>();
  shape.unit = in.get_string();
  shape.has_geometry = in.get<bool>();
  shape.quantity = in.get_string();
  shape.value_unit = in.get_string();
  shape.provenance = in.get_string();
  shape.voxel_size_from = in.get_string();
  shape.origin_from = in.get_string();
  shape.unit_from = in.get_string();
  shape.quantity_from = in.get_string();
  shape.notes.resize(static_cast<std::size_t>(in.get<std::uint64_t>()));
  for (std::string& note : shape.notes) note = in.get_string();
}

std::string worker_parameters(const SlabWorkerSpec& spec) {
  WireWriter out;
  out.put_string(spec.path).put_string(spec.name).put(spec.reader_memory);
  return std::move(out.bytes());
}

std::size_t slab_size(const DenseVolume& shape, std::uint32_t count) {
  return std::size_t{count} * shape.dims[0] * shape.dims[1] * sample_size(shape.type);
}

std::size_t rows_size(const DenseVolume& shape, std::uint32_t rows) {
  return std::size_t{rows} * shape.dims[0] * sample_size(shape.type);
}

}  // namespace

WorkerHandler slab_worker_handler(std::string_view parameters, SlabOpener open, const char* reader_name) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const std::string name = in.get_string();
  const auto memory_bytes = in.get<std::uint64_t>();
  const std::string what = reader_name;
  auto reader = std::make_shared<std::unique_ptr<SlabReader>>();
  return [path, name, memory_bytes, open, what, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      WireWriter info;
      *reader = open(path, name, memory_bytes, info);
      WireWriter reply;
      put_shape(reply, (*reader)->shape());
      reply.put((*reader)->reads_rows());
      out.reply = std::move(reply.bytes()) + info.bytes();
      return;
    }
    const bool rows = operation == kReadRows && *reader && (*reader)->reads_rows();
    if ((operation != kRead && !rows) || !*reader)
      throw Error(ErrorClass::InvalidArgument, what + ": unexpected request " + std::string(1, operation));
    const DenseVolume& shape = (*reader)->shape();
    if (rows) {
      const auto z = in.get<std::uint32_t>();
      const auto y0 = in.get<std::uint32_t>();
      const auto count = in.get<std::uint32_t>();
      if (z >= shape.dims[2] || y0 > shape.dims[1] || count > shape.dims[1] - y0)
        throw Error(ErrorClass::InvalidArgument, what + ": rows outside the volume");
      out.bulk.resize(rows_size(shape, count));
      (*reader)->read_rows(z, y0, count, out.bulk.data());
      return;
    }
    const auto z0 = in.get<std::uint32_t>();
    const auto count = in.get<std::uint32_t>();
    out.bulk.resize(slab_size(shape, count));
    (*reader)->read(z0, count, out.bulk.data());
  };
}

IsolatedSlabReader::IsolatedSlabReader(const SlabWorkerSpec& spec,
                                       const std::function<std::string(WireReader&)>& read_info)
    : volume_(spec.volume), worker_(spec.path, spec.library, spec.kind, worker_parameters(spec), spec.child_memory) {
  WireWriter request;
  request.put(kOpen);
  WireReader reply(worker_.call(request.bytes(), spec.opening));
  get_shape(reply, shape_);
  reads_rows_ = reply.get<bool>();
  const std::string named = read_info(reply);
  if (!named.empty()) volume_ = named;
}

void IsolatedSlabReader::read(std::uint32_t z0, std::uint32_t count, void* out) {
  WireWriter request;
  request.put(kRead).put(z0).put(count);
  worker_.call(request.bytes(),
               "reading slices " + std::to_string(z0) + " .. " + std::to_string(z0 + count) + " of " + volume_, out,
               slab_size(shape_, count));
}

void IsolatedSlabReader::read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) {
  WireWriter request;
  request.put(kReadRows).put(z).put(y0).put(rows);
  worker_.call(request.bytes(),
               "reading slice " + std::to_string(z) + " rows " + std::to_string(y0) + " .. " +
                   std::to_string(y0 + rows) + " of " + volume_,
               out, rows_size(shape_, rows));
}

}  // namespace ivol::convert
