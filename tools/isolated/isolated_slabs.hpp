// A dense volume reader run in a child process (isolated_worker.hpp says
// why): the protocol every such reader speaks, whichever library opens the
// file (libhdf5's datasets, libopenvdb's grids). The parent sends the file,
// the name of the volume in it and the budget the in-process reader weighs
// sizes against; the child opens it, replies with the shape, whether it
// reads by rows and what the library says about the source, then serves
// slabs of slices or bands of rows of one slice.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "isolated_worker.hpp"
#include "slab_io.hpp"
#include "wire.hpp"

namespace ivol::convert {

// Opens `name` in `path` in the child, within `memory_bytes`, and appends
// to `info` what the parent's side needs besides the shape (the source's
// description: stored type, chunking, grid name, ...).
using SlabOpener = std::unique_ptr<SlabReader> (*)(const std::string& path, const std::string& name,
                                                   std::uint64_t memory_bytes, WireWriter& info);

// The child's handler of a slab worker kind made from `parameters`; a
// WorkerFactory is a function of the parameters alone, so each kind wraps
// this with its opener. `reader_name` names the proxy in errors ("isolated
// HDF5 reader").
WorkerHandler slab_worker_handler(std::string_view parameters, SlabOpener open, const char* reader_name);

struct SlabWorkerSpec {
  std::string path;
  std::string name;                 // the dataset or grid; may be empty (the library's default)
  std::uint64_t reader_memory = 0;  // what the in-process reader weighs sizes against
  std::uint64_t child_memory = 0;   // the child's allowance (IsolatedWorker)
  const char* library = "";         // "libhdf5"
  const char* kind = "";            // the registered WorkerKind
  std::string opening;              // for messages: "opening dataset /data"
  std::string volume;               // for messages: "dataset /data", "grid 'density'"
};

// The parent's side: starts the worker, opens the volume, takes the shape
// and hands the rest of the reply (what the opener appended) to
// `read_info`, which returns how later messages name the volume (empty:
// spec.volume).
class IsolatedSlabReader final : public SlabReader {
 public:
  IsolatedSlabReader(const SlabWorkerSpec& spec, const std::function<std::string(WireReader&)>& read_info);
  void read(std::uint32_t z0, std::uint32_t count, void* out) override;
  // By rows where the child's reader reads by rows (its reply to opening
  // says so).
  bool reads_rows() const override { return reads_rows_; }
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override;

 private:
  bool reads_rows_ = false;
  std::string volume_;
  IsolatedWorker worker_;
};

}  // namespace ivol::convert
