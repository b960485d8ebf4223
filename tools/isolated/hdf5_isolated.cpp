// The HDF5 readers as ivol uses them: the in-process readers
// (hdf5_io.cpp, projection_hdf5.cpp) run in a child process, and these
// proxies forward shapes, slabs and rows from it (isolated_worker.hpp says
// why).
#include <memory>
#include <utility>

#include "hdf5_io.hpp"
#include "isolated_slabs.hpp"
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

// The child's side: the in-process reader, and what the parent's side
// reports of the source.
std::unique_ptr<SlabReader> open_volume_in_child(const std::string& path, const std::string& dataset,
                                                 std::uint64_t memory_bytes, WireWriter& info) {
  Hdf5SourceInfo source;
  auto reader = open_hdf5_slabs_in_process(path, dataset, &source, memory_bytes);
  info.put_string(source.stored_type).put(source.narrowed_to_f32).put(source.chunked).put(source.chunk);
  info.put_string(source.filters).put_string(source.dataset);
  return reader;
}

WorkerHandler volume_handler(std::string_view parameters) {
  return slab_worker_handler(parameters, open_volume_in_child, "isolated HDF5 reader");
}

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

// Opens the projections in the child and writes the reply to kOpen: the
// shape (put_scan_shape), then what the layout adds.
using ProjectionOpener = std::unique_ptr<ProjectionReader> (*)(const std::string& path, const DxchangeOptions& options,
                                                               WireWriter& reply);

void put_scan_shape(WireWriter& reply, const ProjectionReader& r) {
  reply.put(r.columns()).put(r.rows()).put<std::uint64_t>(r.view_count()).put(r.quantity());
}

// The child's handler of either projection worker: open, then rows.
WorkerHandler projection_worker_handler(std::string_view parameters, ProjectionOpener open) {
  WireReader in{std::string(parameters)};
  const std::string path = in.get_string();
  const DxchangeOptions options = read_projection_options(in);
  auto reader = std::make_shared<std::unique_ptr<ProjectionReader>>();
  return [path, options, open, reader](std::string_view request, WorkerReply& out) {
    WireReader in{std::string(request)};
    const char operation = in.get<char>();
    if (operation == kOpen) {
      WireWriter reply;
      *reader = open(path, options, reply);
      out.reply = std::move(reply.bytes());
      return;
    }
    if (operation != kRead || !*reader)
      throw Error(ErrorClass::InvalidArgument, "isolated HDF5 reader: unexpected request " + std::string(1, operation));
    serve_rows(**reader, in, out);
  };
}

std::unique_ptr<ProjectionReader> open_dxchange_in_child(const std::string& path, const DxchangeOptions& options,
                                                         WireWriter& reply) {
  DxchangeProjections scan = open_dxchange_projections_in_process(path, options);
  put_scan_shape(reply, *scan.projections);
  reply.put<std::uint64_t>(scan.theta_deg.size());
  for (double angle : scan.theta_deg) reply.put(angle);
  return std::move(scan.projections);
}

WorkerHandler projection_handler(std::string_view parameters) {
  return projection_worker_handler(parameters, open_dxchange_in_child);
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

std::unique_ptr<ProjectionReader> open_scan_in_child(const std::string& path, const DxchangeOptions& options,
                                                     WireWriter& reply) {
  Hdf5Scan scan = open_hdf5_projections_in_process(path, options);
  put_scan_shape(reply, *scan.projections);
  reply.put_string(scan.layout).put_string(scan.entry).put_string(scan.angles_field);
  reply.put<std::uint64_t>(scan.angles_deg.size());
  for (double angle : scan.angles_deg) reply.put(angle);
  for (const LengthField* l : {&scan.pitch_u, &scan.pitch_v, &scan.source_sample, &scan.sample_detector})
    put_length(reply, *l);
  reply.put(scan.flat_images).put(scan.dark_images).put(scan.skipped_images);
  return std::move(scan.projections);
}

WorkerHandler scan_handler(std::string_view parameters) {
  return projection_worker_handler(parameters, open_scan_in_child);
}

// The parent's side of either projection worker: the child may allocate
// options.memory_bytes (recon's --memory; 0: kDefaultChildMemory).
std::unique_ptr<IsolatedWorker> start_projection_worker(const std::string& path, const DxchangeOptions& options,
                                                        const char* kind) {
  return std::make_unique<IsolatedWorker>(path, kLibrary, kind, projection_parameters(path, options),
                                          options.memory_bytes);
}

WireReader open_projections(IsolatedWorker& worker, const std::string& doing) {
  WireWriter request;
  request.put(kOpen);
  return WireReader(worker.call(request.bytes(), doing));
}

ScanShape get_scan_shape(WireReader& reply) {
  ScanShape shape;
  shape.columns = reply.get<int>();
  shape.rows = reply.get<int>();
  shape.views = static_cast<std::size_t>(reply.get<std::uint64_t>());
  shape.quantity = reply.get<StoredQuantity>();
  return shape;
}

const WorkerKind volume_worker(kVolumeWorker, volume_handler);
const WorkerKind projection_worker(kProjectionWorker, projection_handler);
const WorkerKind scan_worker(kScanWorker, scan_handler);

}  // namespace

std::unique_ptr<SlabReader> open_hdf5_slabs(const std::string& path, const std::string& dataset, Hdf5SourceInfo* source,
                                            std::uint64_t memory_bytes) {
  SlabWorkerSpec spec;
  spec.path = path;
  spec.name = dataset;
  spec.reader_memory = memory_bytes ? memory_bytes : kDefaultChildMemory;
  spec.child_memory = memory_bytes;
  spec.library = kLibrary;
  spec.kind = kVolumeWorker;
  spec.opening = "opening dataset " + dataset;
  spec.volume = "dataset " + dataset;
  return std::make_unique<IsolatedSlabReader>(spec, [source](WireReader& reply) {
    Hdf5SourceInfo info;
    info.stored_type = reply.get_string();
    info.narrowed_to_f32 = reply.get<bool>();
    info.chunked = reply.get<bool>();
    info.chunk = reply.get<std::array<unsigned long long, 3>>();
    info.filters = reply.get_string();
    info.dataset = reply.get_string();
    if (source) *source = std::move(info);
    return std::string();
  });
}

DxchangeProjections open_dxchange_projections(const std::string& path, const DxchangeOptions& options) {
  auto worker = start_projection_worker(path, options, kProjectionWorker);
  WireReader reply = open_projections(*worker, "opening the DXchange datasets");
  const ScanShape shape = get_scan_shape(reply);
  DxchangeProjections scan;
  scan.theta_deg.resize(static_cast<std::size_t>(reply.get<std::uint64_t>()));
  for (double& angle : scan.theta_deg) angle = reply.get<double>();
  scan.projections = std::make_unique<IsolatedDxchangeReader>(
      path, shape, std::move(worker), options.dataset.empty() ? std::string("/exchange/data") : options.dataset);
  return scan;
}

Hdf5Scan open_hdf5_projections(const std::string& path, const DxchangeOptions& options) {
  auto worker = start_projection_worker(path, options, kScanWorker);
  WireReader reply = open_projections(*worker, "opening the projections (NXtomo or DXchange)");
  const ScanShape shape = get_scan_shape(reply);
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
