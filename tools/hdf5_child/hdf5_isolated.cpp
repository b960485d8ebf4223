// The HDF5 readers as ivol uses them: the in-process readers
// (hdf5_io.cpp, projection_hdf5.cpp) run in a child process, and these
// proxies forward shapes, slabs and rows from it (isolated_worker.hpp says
// why).
#include <memory>
#include <utility>

#include "hdf5_io.hpp"
#include "isolated_worker.hpp"
#include "ivol/error.hpp"
#include "projection_io.hpp"

namespace ivol::convert {
namespace {

constexpr const char* kLibrary = "libhdf5";
constexpr char kOpen = 'o';
constexpr char kRead = 'r';
constexpr const char* kVolumeWorker = "hdf5-volume";
constexpr const char* kProjectionWorker = "hdf5-dxchange";
constexpr const char* kScanWorker = "hdf5-scan";

// --- Volumes ----------------------------------------------------------------

// The parameters of a volume worker: the file, the dataset, the memory
// budget its reader checks sizes against.
std::string volume_parameters(const std::string& path, const std::string& dataset, std::uint64_t memory_bytes) {
  WireWriter out;
  out.put_string(path).put_string(dataset).put(memory_bytes);
  return std::move(out.bytes());
}

WorkerHandler volume_handler(std::string_view parameters) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const std::string dataset = in.get_string();
  const auto memory_bytes = in.get<std::uint64_t>();
  auto reader = std::make_shared<std::unique_ptr<SlabReader>>();
  return [path, dataset, memory_bytes, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      Hdf5SourceInfo source;
      *reader = open_hdf5_slabs_in_process(path, dataset, &source, memory_bytes);
      const DenseVolume& shape = (*reader)->shape();
      WireWriter reply;
      reply.put(shape.dims).put(shape.type).put(shape.voxel_size).put(shape.origin).put_string(shape.unit);
      reply.put(shape.has_geometry).put_string(source.stored_type).put(source.narrowed_to_f32).put(source.chunked);
      reply.put(source.chunk).put_string(source.filters);
      reply.put_string(shape.quantity).put_string(shape.value_unit).put_string(shape.provenance);
      reply.put_string(shape.voxel_size_from).put_string(shape.origin_from).put_string(shape.unit_from);
      reply.put_string(shape.quantity_from).put_string(source.dataset);
      out.reply = std::move(reply.bytes());
      return;
    }
    if (operation != kRead || !*reader)
      throw Error(ErrorClass::InvalidArgument, "isolated HDF5 reader: unexpected request " + std::string(1, operation));
    const auto z0 = in.get<std::uint32_t>();
    const auto count = in.get<std::uint32_t>();
    const DenseVolume& shape = (*reader)->shape();
    out.bulk.resize(std::size_t{count} * shape.dims[0] * shape.dims[1] * sample_size(shape.type));
    (*reader)->read(z0, count, out.bulk.data());
  };
}

class IsolatedHdf5SlabReader final : public SlabReader {
 public:
  IsolatedHdf5SlabReader(const std::string& path, const std::string& dataset, Hdf5SourceInfo* source,
                         std::uint64_t memory_bytes)
      : dataset_(dataset),
        worker_(path, kLibrary, kVolumeWorker,
                volume_parameters(path, dataset, memory_bytes ? memory_bytes : kDefaultChildMemory), memory_bytes) {
    WireWriter request;
    request.put(kOpen);
    WireReader reply(worker_.call(request.bytes(), "opening dataset " + dataset));
    shape_.dims = reply.get<Dims>();
    shape_.type = reply.get<SampleType>();
    shape_.voxel_size = reply.get<std::array<double, 3>>();
    shape_.origin = reply.get<std::array<double, 3>>();
    shape_.unit = reply.get_string();
    shape_.has_geometry = reply.get<bool>();
    Hdf5SourceInfo info;
    info.stored_type = reply.get_string();
    info.narrowed_to_f32 = reply.get<bool>();
    info.chunked = reply.get<bool>();
    info.chunk = reply.get<std::array<unsigned long long, 3>>();
    info.filters = reply.get_string();
    shape_.quantity = reply.get_string();
    shape_.value_unit = reply.get_string();
    shape_.provenance = reply.get_string();
    shape_.voxel_size_from = reply.get_string();
    shape_.origin_from = reply.get_string();
    shape_.unit_from = reply.get_string();
    shape_.quantity_from = reply.get_string();
    info.dataset = reply.get_string();
    if (source) *source = std::move(info);
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    WireWriter request;
    request.put(kRead).put(z0).put(count);
    const std::size_t bytes = std::size_t{count} * shape_.dims[0] * shape_.dims[1] * sample_size(shape_.type);
    worker_.call(
        request.bytes(),
        "reading slices " + std::to_string(z0) + " .. " + std::to_string(z0 + count) + " of dataset " + dataset_, out,
        bytes);
  }

 private:
  std::string dataset_;
  IsolatedWorker worker_;
};

// --- DXchange projections ---------------------------------------------------

std::string projection_parameters(const std::string& path, const DxchangeOptions& options) {
  WireWriter out;
  out.put_string(path).put(options.assume_line_integrals).put(options.minimum_signal).put_string(options.dataset);
  return std::move(out.bytes());
}

// The child's side of projection_parameters (after the path).
DxchangeOptions read_projection_options(WireReader& in) {
  DxchangeOptions options;
  options.assume_line_integrals = in.get<bool>();
  options.minimum_signal = in.get<double>();
  options.dataset = in.get_string();
  return options;
}

// Reads rows of the reader the child opened, converted to line integrals
// there: the same requests as the DXchange worker's.
void serve_rows(ProjectionReader& r, WireReader& in, WorkerReply& out) {
  const auto view = in.get<std::uint64_t>();
  const int row_begin = in.get<int>();
  const int row_end = in.get<int>();
  const std::uint64_t clamped_before = r.clamped_pixels();
  const std::size_t count = static_cast<std::size_t>(row_end - row_begin) * static_cast<std::size_t>(r.columns());
  out.bulk.resize(count * sizeof(float));
  r.read_rows(static_cast<std::size_t>(view), row_begin, row_end, reinterpret_cast<float*>(out.bulk.data()));
  WireWriter reply;
  reply.put<std::uint64_t>(r.clamped_pixels() - clamped_before);
  out.reply = std::move(reply.bytes());
}

WorkerHandler projection_handler(std::string_view parameters) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const DxchangeOptions options = read_projection_options(in);
  auto reader = std::make_shared<std::unique_ptr<ProjectionReader>>();
  return [path, options, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      DxchangeProjections scan = open_dxchange_projections_in_process(path, options);
      *reader = std::move(scan.projections);
      const ProjectionReader& r = **reader;
      WireWriter reply;
      reply.put(r.columns()).put(r.rows()).put<std::uint64_t>(r.view_count()).put(r.quantity());
      reply.put<std::uint64_t>(scan.theta_deg.size());
      for (double angle : scan.theta_deg) reply.put(angle);
      out.reply = std::move(reply.bytes());
      return;
    }
    if (operation != kRead || !*reader)
      throw Error(ErrorClass::InvalidArgument, "isolated HDF5 reader: unexpected request " + std::string(1, operation));
    serve_rows(**reader, in, out);
  };
}

struct ScanShape {
  int columns = 0;
  int rows = 0;
  std::size_t views = 0;
  StoredQuantity quantity = StoredQuantity::LineIntegrals;
};

// The child converts intensities to line integrals (it holds the flat and
// dark fields); this side passes the floats on. float → double → float is
// exact, so the values are those of the in-process reader.
class IsolatedDxchangeReader final : public ProjectionReader {
 public:
  IsolatedDxchangeReader(const std::string& path, const ScanShape& shape, std::unique_ptr<IsolatedWorker> worker,
                         std::string dataset = "/exchange/data")
      : ProjectionReader(path, shape.columns, shape.rows, shape.views),
        quantity_(shape.quantity),
        worker_(std::move(worker)),
        dataset_(std::move(dataset)) {}

  StoredQuantity quantity() const override { return quantity_; }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    WireWriter request;
    request.put(kRead).put<std::uint64_t>(view).put(row_begin).put(row_end);
    const std::size_t count = static_cast<std::size_t>(row_end - row_begin) * static_cast<std::size_t>(columns_);
    line_integrals_.resize(count);
    WireReader reply(worker_->call(request.bytes(),
                                   "reading view " + std::to_string(view) + " rows " + std::to_string(row_begin) +
                                       ".." + std::to_string(row_end) + " of dataset " + dataset_,
                                   line_integrals_.data(), count * sizeof(float)));
    count_clamped(reply.get<std::uint64_t>());
    for (std::size_t i = 0; i < count; ++i) out[i] = line_integrals_[i];
  }

 private:
  StoredQuantity quantity_;
  std::unique_ptr<IsolatedWorker> worker_;
  std::string dataset_;
  std::vector<float> line_integrals_;
};

// --- HDF5 scans of either layout (NXtomo or DXchange) ----------------------

void put_length(WireWriter& out, const LengthField& length) {
  out.put(length.present).put(length.mm).put_string(length.field);
}

LengthField get_length(WireReader& in) {
  LengthField length;
  length.present = in.get<bool>();
  length.mm = in.get<double>();
  length.field = in.get_string();
  return length;
}

WorkerHandler scan_handler(std::string_view parameters) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const DxchangeOptions options = read_projection_options(in);
  auto reader = std::make_shared<std::unique_ptr<ProjectionReader>>();
  return [path, options, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      Hdf5Scan scan = open_hdf5_projections_in_process(path, options);
      *reader = std::move(scan.projections);
      const ProjectionReader& r = **reader;
      WireWriter reply;
      reply.put(r.columns()).put(r.rows()).put<std::uint64_t>(r.view_count()).put(r.quantity());
      reply.put_string(scan.layout).put_string(scan.entry).put_string(scan.angles_field);
      reply.put<std::uint64_t>(scan.angles_deg.size());
      for (double angle : scan.angles_deg) reply.put(angle);
      for (const LengthField* l : {&scan.pitch_u, &scan.pitch_v, &scan.source_sample, &scan.sample_detector})
        put_length(reply, *l);
      reply.put(scan.flat_images).put(scan.dark_images).put(scan.skipped_images);
      out.reply = std::move(reply.bytes());
      return;
    }
    if (operation != kRead || !*reader)
      throw Error(ErrorClass::InvalidArgument, "isolated HDF5 reader: unexpected request " + std::string(1, operation));
    serve_rows(**reader, in, out);
  };
}

const WorkerKind volume_worker(kVolumeWorker, volume_handler);
const WorkerKind projection_worker(kProjectionWorker, projection_handler);
const WorkerKind scan_worker(kScanWorker, scan_handler);

}  // namespace

std::unique_ptr<SlabReader> open_hdf5_slabs(const std::string& path, const std::string& dataset, Hdf5SourceInfo* source,
                                            std::uint64_t memory_bytes) {
  return std::make_unique<IsolatedHdf5SlabReader>(path, dataset, source, memory_bytes);
}

DxchangeProjections open_dxchange_projections(const std::string& path, const DxchangeOptions& options) {
  auto worker = std::make_unique<IsolatedWorker>(path, kLibrary, kProjectionWorker,
                                                 projection_parameters(path, options), options.memory_bytes);
  WireWriter request;
  request.put(kOpen);
  WireReader reply(worker->call(request.bytes(), "opening the DXchange datasets"));
  ScanShape shape;
  shape.columns = reply.get<int>();
  shape.rows = reply.get<int>();
  shape.views = static_cast<std::size_t>(reply.get<std::uint64_t>());
  shape.quantity = reply.get<StoredQuantity>();
  DxchangeProjections scan;
  scan.theta_deg.resize(static_cast<std::size_t>(reply.get<std::uint64_t>()));
  for (double& angle : scan.theta_deg) angle = reply.get<double>();
  scan.projections = std::make_unique<IsolatedDxchangeReader>(
      path, shape, std::move(worker), options.dataset.empty() ? std::string("/exchange/data") : options.dataset);
  return scan;
}

Hdf5Scan open_hdf5_projections(const std::string& path, const DxchangeOptions& options) {
  auto worker = std::make_unique<IsolatedWorker>(path, kLibrary, kScanWorker, projection_parameters(path, options),
                                                 options.memory_bytes);
  WireWriter request;
  request.put(kOpen);
  WireReader reply(worker->call(request.bytes(), "opening the projections (NXtomo or DXchange)"));
  ScanShape shape;
  shape.columns = reply.get<int>();
  shape.rows = reply.get<int>();
  shape.views = static_cast<std::size_t>(reply.get<std::uint64_t>());
  shape.quantity = reply.get<StoredQuantity>();
  Hdf5Scan scan;
  scan.layout = reply.get_string();
  scan.entry = reply.get_string();
  scan.angles_field = reply.get_string();
  scan.angles_deg.resize(static_cast<std::size_t>(reply.get<std::uint64_t>()));
  for (double& angle : scan.angles_deg) angle = reply.get<double>();
  for (LengthField* l : {&scan.pitch_u, &scan.pitch_v, &scan.source_sample, &scan.sample_detector})
    *l = get_length(reply);
  scan.flat_images = reply.get<std::uint64_t>();
  scan.dark_images = reply.get<std::uint64_t>();
  scan.skipped_images = reply.get<std::uint64_t>();
  const std::string dataset = scan.layout == "NXtomo"   ? scan.entry + "/instrument/detector/data"
                              : options.dataset.empty() ? std::string("/exchange/data")
                                                        : options.dataset;
  scan.projections = std::make_unique<IsolatedDxchangeReader>(path, shape, std::move(worker), dataset);
  return scan;
}

}  // namespace ivol::convert
