// ivol._ivol: the compiled half of the Python package. It wraps one
// ivol::Reader (which is not thread-safe: the Python half opens one per
// thread), ivol::check_file and the octree writer. Indexing, levels and the
// exception classes live in Python (ivol/__init__.py); this file only moves
// boxes of voxels between libformat and numpy, with the GIL released while
// libformat reads, decodes or writes.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "ivol/binary16.hpp"
#include "ivol/check.hpp"
#include "ivol/encoding.hpp"
#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/structures.hpp"
#include "output_memory.hpp"

namespace py = pybind11;

namespace {

// numpy arrays that own the std::vector libformat returned: no copy. The
// strides are given, from sizeof(T): left out, pybind11 before 2.12 (Debian
// 12 has 2.10) takes them from the dtype's item size as numpy 1 laid out its
// descriptor, which reads 0 under numpy 2 — every element would alias the
// first (python_numpy2 in tests/CMakeLists.txt keeps that from coming back).
template <typename T>
py::array owning_array(std::vector<T>&& data, const std::vector<py::ssize_t>& shape, const py::dtype& dtype) {
  std::vector<py::ssize_t> strides(shape.size());
  py::ssize_t stride = sizeof(T);
  for (std::size_t a = shape.size(); a-- > 0;) {
    strides[a] = stride;
    stride *= shape[a];
  }
  auto* held = new std::vector<T>(std::move(data));
  py::capsule owner(held, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array(dtype, shape, strides, held->data(), owner);
}

// An uninitialised C-order array of `shape` and `dtype` (T's size) for a
// read to fill: a large one in memory of output_memory.hpp, faulted in on
// several threads with the GIL released, a small one from numpy.
template <typename T>
py::array output_array(const std::vector<py::ssize_t>& shape, const py::dtype& dtype) {
  std::vector<py::ssize_t> strides(shape.size());
  py::ssize_t stride = sizeof(T);
  for (std::size_t a = shape.size(); a-- > 0;) {
    strides[a] = stride;
    stride *= shape[a];
  }
  const auto bytes = static_cast<std::size_t>(stride);
  if (bytes < ivol_python::kMappedOutputBytes) return py::array(dtype, shape, strides);
  struct Mapping {
    void* data;
    std::size_t bytes;
  };
  auto mapping = std::make_unique<Mapping>(Mapping{nullptr, bytes});
  {
    py::gil_scoped_release release;
    mapping->data = ivol_python::map_output(bytes);
  }
  void* data = mapping->data;
  py::capsule owner(mapping.get(), [](void* p) {
    auto* m = static_cast<Mapping*>(p);
    ivol_python::unmap_output(m->data, m->bytes);
    delete m;
  });
  mapping.release();
  return py::array(dtype, shape, strides, data, owner);
}

// Messages quote bytes of the file (a metadata block that is not UTF-8):
// such bytes become \xNN escapes rather than a UnicodeDecodeError.
py::str text(const std::string& s) {
  PyObject* o = PyUnicode_DecodeUTF8(s.data(), static_cast<Py_ssize_t>(s.size()), "backslashreplace");
  if (!o) throw py::error_already_set();
  return py::reinterpret_steal<py::str>(o);
}

ivol::Box make_box(const std::array<std::uint32_t, 3>& lo, const std::array<std::uint32_t, 3>& hi) {
  ivol::Box box;
  box.lo = lo;
  box.hi = hi;
  return box;
}

// The regions a salvaging read filled from a coarser level, as dicts with
// lo and hi (x, y, z, in the coordinates of the read's level), the octree
// level where the damage was met and libformat's message.
py::list damaged_list(const std::vector<ivol::DamagedRegion>& damaged) {
  py::list out;
  for (const ivol::DamagedRegion& d : damaged) {
    py::dict e;
    e["lo"] = py::make_tuple(d.region.lo[0], d.region.lo[1], d.region.lo[2]);
    e["hi"] = py::make_tuple(d.region.hi[0], d.region.hi[1], d.region.hi[2]);
    e["level"] = d.level;
    e["message"] = text(d.message);
    out.append(e);
  }
  return out;
}

py::dict salvage_dict(const ivol::SalvageInfo& s) {
  py::dict d;
  d["reason"] = text(s.reason);
  d["blocks_found"] = s.blocks_found;
  d["blocks_used"] = s.blocks_used;
  d["bytes_lost"] = s.bytes_lost;
  py::list gaps;
  for (const auto& g : s.gaps) gaps.append(py::make_tuple(g.first, g.second));
  d["gaps"] = gaps;
  d["metadata"] = s.metadata;
  d["finest_complete_level"] = s.finest_complete_lod;
  d["values_found"] = s.values_found;
  d["values_total"] = s.values_total;
  py::list notes;
  for (const std::string& n : s.notes) notes.append(text(n));
  d["notes"] = notes;
  return d;
}

// One Reader and the lock that keeps io_stats() from racing a read of
// another thread that was handed this object.
class PyReader {
 public:
  PyReader(const std::string& path, std::uint64_t cache_bytes, bool salvage) {
    ivol::ReaderOptions options;
    options.cache_bytes = cache_bytes;
    options.salvage = salvage;
    py::gil_scoped_release release;
    reader_ = std::make_unique<ivol::Reader>(path, options);
  }

  // Physical values of the box [lo, hi) (x, y, z) of level `lod`, as a
  // float32 array [z][y][x]. With `salvage`, damaged or missing blocks take
  // a coarser level's values and the result is (array, damaged regions).
  py::object read(const std::array<std::uint32_t, 3>& lo, const std::array<std::uint32_t, 3>& hi, unsigned lod,
                  bool salvage) {
    std::vector<ivol::DamagedRegion> damaged;
    py::array array;
    if (within_level(lo, hi, lod)) {
      // Read into the array's own memory: no vector zeroed first and
      // handed over.
      py::array out = output_array<float>(shape_of(lo, hi), py::dtype::of<float>());
      auto* data = static_cast<float*>(out.mutable_data());
      {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(mutex_);
        reader_->read_box_into(make_box(lo, hi), data, lod, salvage ? &damaged : nullptr);
      }
      array = std::move(out);
    } else {
      // read_box refuses the box (the error the caller expects) before
      // allocating anything.
      std::vector<float> values;
      {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(mutex_);
        values = reader_->read_box(make_box(lo, hi), lod, salvage ? &damaged : nullptr);
      }
      array = owning_array(std::move(values), shape_of(lo, hi), py::dtype::of<float>());
    }
    if (!salvage) return std::move(array);
    return py::make_tuple(array, damaged_list(damaged));
  }

  // Whether [lo, hi) is a box of level `lod` that is neither empty nor
  // outside it.
  bool within_level(const std::array<std::uint32_t, 3>& lo, const std::array<std::uint32_t, 3>& hi,
                    unsigned lod) const {
    const ivol::VolumeLayout& v = reader_->layout();
    if (lod > v.depth) return false;
    const ivol::Dims d = ivol::lod_dims(v.dims, lod);
    for (int a = 0; a < 3; ++a)
      if (lo[a] >= hi[a] || hi[a] > d[a]) return false;
    return true;
  }

  // Stored bits of the box, little-endian, encoding_width() bytes a voxel,
  // as a uint8 array the Python half views with the encoding's dtype.
  py::object read_bits(const std::array<std::uint32_t, 3>& lo, const std::array<std::uint32_t, 3>& hi, unsigned lod,
                       bool salvage) {
    std::vector<ivol::DamagedRegion> damaged;
    py::array array;
    if (within_level(lo, hi, lod)) {
      // Into the array's own memory, as read() does: no zeroed vector first.
      const std::uint64_t bytes = std::uint64_t{hi[0] - lo[0]} * (hi[1] - lo[1]) * (hi[2] - lo[2]) *
                                  ivol::encoding_width(reader_->layout().encoding);
      py::array out = output_array<std::uint8_t>({static_cast<py::ssize_t>(bytes)}, py::dtype::of<std::uint8_t>());
      auto* data = static_cast<std::uint8_t*>(out.mutable_data());
      {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(mutex_);
        reader_->read_box_bits_into(make_box(lo, hi), data, lod, salvage ? &damaged : nullptr);
      }
      array = std::move(out);
    } else {
      std::vector<std::uint8_t> bits;
      {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(mutex_);
        bits = reader_->read_box_bits(make_box(lo, hi), lod, salvage ? &damaged : nullptr);
      }
      const auto n = static_cast<py::ssize_t>(bits.size());
      array = owning_array(std::move(bits), {n}, py::dtype::of<std::uint8_t>());
    }
    if (!salvage) return std::move(array);
    return py::make_tuple(array, damaged_list(damaged));
  }

  py::dict info() const {
    const ivol::VolumeLayout& v = reader_->layout();
    const ivol::FileInfo& f = reader_->info();
    py::dict d;
    d["dims"] = py::make_tuple(v.dims[0], v.dims[1], v.dims[2]);
    d["depth"] = v.depth;
    d["structure"] = ivol::structure_name(v.kind);
    d["encoding"] = ivol::encoding_name(v.encoding);
    d["value_scale"] = v.value_scale;
    d["value_offset"] = v.value_offset;
    d["version"] = py::make_tuple(f.version_major, f.version_minor);
    d["file_size"] = f.file_size;
    d["block_count"] = f.blocks.size();
    d["metadata_json"] = reader_->metadata().to_json().dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    d["salvage"] = f.salvage ? py::object(salvage_dict(*f.salvage)) : py::object(py::none());
    d["metadata_problem"] = reader_->metadata_problem();
    return d;
  }

  py::dict io_stats() {
    ivol::IoStats s;
    {
      py::gil_scoped_release release;
      std::lock_guard<std::mutex> lock(mutex_);
      s = reader_->io_stats();
    }
    py::dict d;
    d["bytes_read"] = s.bytes_read;
    d["blocks_decoded"] = s.blocks_decoded;
    d["cache_hits"] = s.cache_hits;
    return d;
  }

  void reset_io_stats() {
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(mutex_);
    reader_->reset_io_stats();
  }

 private:
  static std::vector<py::ssize_t> shape_of(const std::array<std::uint32_t, 3>& lo,
                                           const std::array<std::uint32_t, 3>& hi) {
    return {static_cast<py::ssize_t>(hi[2] - lo[2]), static_cast<py::ssize_t>(hi[1] - lo[1]),
            static_cast<py::ssize_t>(hi[0] - lo[0])};
  }
  std::unique_ptr<ivol::Reader> reader_;
  std::mutex mutex_;
};

py::dict check(const std::string& path) {
  ivol::CheckReport report;
  {
    py::gil_scoped_release release;
    report = ivol::check_file(path);
  }
  py::list problems;
  for (const ivol::CheckProblem& p : report.problems) {
    py::dict e;
    e["error_class"] = ivol::error_class_name(p.error_class);
    e["message"] = text(p.message);
    problems.append(e);
  }
  py::dict d;
  d["problems"] = problems;
  d["blocks_checked"] = report.blocks_checked;
  d["blocks_damaged"] = report.blocks_damaged;
  d["tree_checked"] = report.tree_checked;
  return d;
}

// The samples `ivol convert` reads from a raw file, by the names it records
// in structure.source_encoding.
enum class Sample { U8, U16, I16, F16, F32 };

Sample sample_of(const std::string& name) {
  if (name == "u8") return Sample::U8;
  if (name == "u16") return Sample::U16;
  if (name == "i16") return Sample::I16;
  if (name == "f16") return Sample::F16;
  if (name == "f32") return Sample::F32;
  throw ivol::Error(ivol::ErrorClass::InvalidArgument, "unknown sample type " + name);
}

double sample_value(Sample type, const std::uint8_t* p) {
  switch (type) {
    case Sample::U8:
      return *p;
    case Sample::U16: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case Sample::I16: {
      std::int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case Sample::F16: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return ivol::binary16_to_double(v);
    }
    case Sample::F32: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
  }
  return 0.0;
}

// Writes a C-contiguous [z][y][x] array as `ivol convert` writes the same raw
// samples (tools/convert/ivol_io.cpp: import_to_ivol, finish_import): the
// same streaming octree writer, build options and metadata, so that with the
// same provenance the files are equal byte for byte.
py::dict write_volume(const std::string& path, const py::buffer& array, const std::string& sample_name,
                      const std::array<std::uint32_t, 3>& dims, const std::string& encoding_name,
                      const std::array<double, 3>& voxel_size, const std::array<double, 3>& origin,
                      const std::string& unit, const std::string& quantity, const std::string& value_unit,
                      const std::string& provenance_json, std::uint32_t block_bytes, bool byte_planes) {
  const Sample type = sample_of(sample_name);
  const std::size_t size = type == Sample::U8 ? 1 : type == Sample::F32 ? 4 : 2;
  const py::buffer_info buffer = array.request();
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  if (static_cast<std::uint64_t>(buffer.size) * buffer.itemsize != slice * dims[2] * size)
    throw ivol::Error(ivol::ErrorClass::InvalidArgument, path + ": the array's size does not match its shape");
  const auto* samples = static_cast<const std::uint8_t*>(buffer.ptr);

  ivol::StreamingOptions streaming;
  const bool integer = type == Sample::U8 || type == Sample::U16 || type == Sample::I16;
  if (encoding_name.empty()) {
    streaming.build.encoding = integer               ? ivol::ValueEncoding::UInt16
                               : type == Sample::F16 ? ivol::ValueEncoding::Binary16
                                                     : ivol::ValueEncoding::Float32;
  } else {
    const auto parsed = ivol::parse_encoding(encoding_name);
    if (!parsed)
      throw ivol::Error(ivol::ErrorClass::InvalidArgument,
                        "encoding: '" + encoding_name + "' is not binary16, uint16 or float32");
    streaming.build.encoding = *parsed;
  }
  const bool codes = streaming.build.encoding == ivol::ValueEncoding::UInt16;
  if (codes && !integer)
    throw ivol::Error(ivol::ErrorClass::InvalidArgument, "encoding uint16 needs integer samples; this array holds " +
                                                             sample_name + " (use binary16 or float32)");
  if (codes && type == Sample::I16) streaming.build.value_offset = -32768.0;
  if (block_bytes) streaming.write.block_bytes = block_bytes;
  streaming.write.byte_planes = byte_planes;

  ivol::Metadata metadata;
  metadata.voxel_size = voxel_size;
  metadata.origin = origin;
  metadata.unit = unit;
  if (!quantity.empty()) metadata.quantity = quantity;
  if (!value_unit.empty()) metadata.value_unit = value_unit;
  metadata.provenance = ivol::default_provenance();
  if (!provenance_json.empty()) metadata.provenance.update(nlohmann::json::parse(provenance_json));
  metadata.structure["kind"] = "octree";
  metadata.structure["source_encoding"] = sample_name;

  ivol::StreamingResult result;
  {
    py::gil_scoped_release release;
    ivol::StreamingOctreeWriter writer(path, ivol::Dims{dims[0], dims[1], dims[2]}, streaming);
    std::vector<float> values;
    std::vector<std::uint16_t> code_values;
    while (writer.next_slab_count() > 0) {
      const std::uint64_t first = std::uint64_t{writer.next_slab_first()} * slice;
      const std::uint64_t n = std::uint64_t{writer.next_slab_count()} * slice;
      if (codes) {
        code_values.resize(n);
        for (std::uint64_t i = 0; i < n; ++i)
          code_values[i] = static_cast<std::uint16_t>(sample_value(type, samples + (first + i) * size) -
                                                      streaming.build.value_offset);
        writer.add_slab(code_values.data());
      } else if (type == Sample::F32) {
        writer.add_slab(reinterpret_cast<const float*>(samples) + first);
      } else if (type == Sample::F16) {
        // Bit for bit, not through double: converting a signalling NaN
        // between float and double quiets it, and the file must keep it.
        values.resize(n);
        for (std::uint64_t i = 0; i < n; ++i) {
          std::uint16_t bits;
          std::memcpy(&bits, samples + (first + i) * size, 2);
          values[i] = ivol::binary16_to_float(bits);
        }
        writer.add_slab(values.data());
      } else {
        values.resize(n);
        for (std::uint64_t i = 0; i < n; ++i)
          values[i] = static_cast<float>(sample_value(type, samples + (first + i) * size));
        writer.add_slab(values.data());
      }
    }
    result = writer.finish(metadata, [](ivol::Metadata& m, const ivol::StreamingResult& r) {
      m.structure["lossless"] = r.lossless;
      m.structure["max_abs_error"] = r.max_abs_error;
    });
  }
  py::dict d;
  d["file_bytes"] = result.write.file_bytes;
  d["lossless"] = result.lossless;
  d["max_abs_error"] = result.max_abs_error;
  d["encoding"] = ivol::encoding_name(streaming.build.encoding);
  return d;
}

// Writes `values` ([z][y][x] float32) as a structure of `kind_name`
// generated from a need mask ([k][j][i] cells of `factor` voxels a side,
// non-zero where full resolution is needed), each structure voxel the mean
// of the voxels it covers: what `ivol recon --structure` does with a
// reconstruction (generate_structure, then write_structure), with the mask
// given instead of found on a preview.
py::dict write_grid(const std::string& path, const py::array_t<float, py::array::c_style>& values,
                    const std::string& kind_name, const py::array_t<std::uint8_t, py::array::c_style>& need,
                    std::uint32_t factor, std::uint32_t nested_cell, std::uint32_t max_interval,
                    const std::string& encoding_name, const std::array<double, 3>& voxel_size,
                    const std::array<double, 3>& origin, const std::string& unit, const std::string& quantity,
                    const std::string& value_unit, const std::string& provenance_json, std::uint32_t block_bytes) {
  ivol::StructureKind kind{};
  if (!ivol::parse_structure(kind_name, kind))
    throw ivol::Error(ivol::ErrorClass::InvalidArgument,
                      path + ": structure '" + kind_name + "' is not octree, regular, rectilinear or nested");
  if (values.ndim() != 3 || need.ndim() != 3)
    throw ivol::Error(ivol::ErrorClass::InvalidArgument, path + ": values and need need 3 dimensions (z, y, x)");
  ivol::NeedMask mask;
  mask.factor = factor;
  for (int a = 0; a < 3; ++a) {
    mask.dims[a] = static_cast<std::uint32_t>(values.shape(2 - a));
    mask.cells[a] = (mask.dims[a] + factor - 1) / factor;
    if (static_cast<std::uint64_t>(need.shape(2 - a)) != mask.cells[a])
      throw ivol::Error(ivol::ErrorClass::InvalidArgument,
                        path + ": need has " + std::to_string(need.shape(2 - a)) + " cells along axis " +
                            std::to_string(2 - a) + "; ceil(" + std::to_string(mask.dims[a]) + " / " +
                            std::to_string(factor) + ") = " + std::to_string(mask.cells[a]) + " expected");
  }
  mask.need.assign(need.data(), need.data() + need.size());

  ivol::StreamingOptions options;
  const auto parsed = ivol::parse_encoding(encoding_name);
  if (!parsed || *parsed == ivol::ValueEncoding::UInt16)
    throw ivol::Error(ivol::ErrorClass::InvalidArgument,
                      path + ": encoding '" + encoding_name +
                          "' for a structure: binary16 or float32 (its coarse voxels are means, not integers)");
  options.build.encoding = *parsed;
  if (block_bytes) options.write.block_bytes = block_bytes;

  ivol::Metadata metadata;
  metadata.voxel_size = voxel_size;
  metadata.origin = origin;
  metadata.unit = unit;
  if (!quantity.empty()) metadata.quantity = quantity;
  if (!value_unit.empty()) metadata.value_unit = value_unit;
  metadata.provenance = ivol::default_provenance();
  if (!provenance_json.empty()) metadata.provenance.update(nlohmann::json::parse(provenance_json));
  metadata.structure["kind"] = kind_name;

  ivol::StreamingResult result;
  std::uint64_t structure_voxels = 0;
  {
    py::gil_scoped_release release;
    ivol::GenerationOptions generation;
    generation.nested_cell = nested_cell;
    generation.rectilinear_max_interval = max_interval;
    std::unique_ptr<ivol::VoxelStructure> structure = ivol::generate_structure(kind, mask, generation);
    structure->sample_dense(values.data());
    structure_voxels = structure->voxel_count();
    result = ivol::write_structure(*structure, path, metadata, options);
  }
  py::dict d;
  d["file_bytes"] = result.write.file_bytes;
  d["max_abs_error"] = result.max_abs_error;
  d["structure_voxels"] = structure_voxels;
  d["encoding"] = ivol::encoding_name(options.build.encoding);
  return d;
}

}  // namespace

PYBIND11_MODULE(_ivol, m) {
  m.doc() = "Compiled part of the ivol package; use the ivol module.";
  // ivol::Error becomes the Python class of its spec error class
  // (ivol._errors.error_for), raised with the message and the class name.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ivol::Error& e) {
      const char* name = ivol::error_class_name(e.error_class());
      py::object cls = py::module_::import("ivol._errors").attr("error_for")(name);
      PyErr_SetObject(cls.ptr(), py::make_tuple(text(e.what()), name).ptr());
    } catch (const nlohmann::json::exception& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });

  py::class_<PyReader>(m, "Reader")
      .def(py::init<const std::string&, std::uint64_t, bool>(), py::arg("path"), py::arg("cache_bytes"),
           py::arg("salvage"))
      .def("read", &PyReader::read)
      .def("read_bits", &PyReader::read_bits)
      .def("info", &PyReader::info)
      .def("io_stats", &PyReader::io_stats)
      .def("reset_io_stats", &PyReader::reset_io_stats);
  m.def("check", &check);
  m.def("write", &write_volume);
  m.def("write_grid", &write_grid);
  m.def("library_version", &ivol::library_version);
}
