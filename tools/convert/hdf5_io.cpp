#include "hdf5_io.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <utility>
#include <vector>

#include "ivol/error.hpp"
#include "staged_file.hpp"

namespace ivol::convert {
namespace {

// Owns an HDF5 identifier and closes it with the matching H5?close.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() { reset(); }
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, -1)), close_(other.close_) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      reset();
      id_ = std::exchange(other.id_, -1);
      close_ = other.close_;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  // Gives up ownership, for a close whose result must be checked.
  hid_t release() { return std::exchange(id_, -1); }
  void reset() {
    if (id_ >= 0 && close_) close_(id_);
    id_ = -1;
  }

 private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

// HDF5 prints its whole error stack to stderr by default; we throw our own
// messages instead, so silence it for the duration of a call.
class QuietHdf5Errors {
 public:
  QuietHdf5Errors() {
    H5Eget_auto2(H5E_DEFAULT, &old_function_, &old_data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietHdf5Errors() { H5Eset_auto2(H5E_DEFAULT, old_function_, old_data_); }
  QuietHdf5Errors(const QuietHdf5Errors&) = delete;
  QuietHdf5Errors& operator=(const QuietHdf5Errors&) = delete;

 private:
  H5E_auto2_t old_function_ = nullptr;
  void* old_data_ = nullptr;
};

// The most specific description on HDF5's error stack, to explain a failure.
std::string hdf5_reason() {
  std::string reason;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned depth, const H5E_error2_t* error, void* out) -> herr_t {
        if (depth == 0 && error->desc) *static_cast<std::string*>(out) = error->desc;
        return 0;
      },
      &reason);
  return reason.empty() ? std::string() : " (HDF5: " + reason + ")";
}

std::string where(const std::string& path, const std::string& dataset) { return path + ": dataset " + dataset; }

// IEEE 754 binary16 in native byte order, built as h5py builds its float16.
Handle make_half_type() {
  Handle type(H5Tcopy(H5T_NATIVE_FLOAT), H5Tclose);
  H5Tset_fields(type.get(), 15, 10, 5, 0, 10);
  H5Tset_size(type.get(), 2);
  H5Tset_ebias(type.get(), 15);
  return type;
}

bool is_ieee_half(hid_t type) {
  std::size_t sign_position, exponent_position, exponent_size, mantissa_position, mantissa_size;
  if (H5Tget_fields(type, &sign_position, &exponent_position, &exponent_size, &mantissa_position, &mantissa_size) < 0)
    return false;
  return sign_position == 15 && exponent_position == 10 && exponent_size == 5 && mantissa_position == 0 &&
         mantissa_size == 10 && H5Tget_ebias(type) == 15;
}

// How the stored sample type maps to a DenseVolume sample type and the memory
// type HDF5 converts to (byte order included).
struct SampleMapping {
  SampleType sample;
  Handle memory_type;  // owned copy, so that the half type can be freed
  std::string stored_name;
  bool narrowed = false;
};

SampleMapping map_sample_type(hid_t file_type, const std::string& context) {
  const H5T_class_t type_class = H5Tget_class(file_type);
  const std::size_t size = H5Tget_size(file_type);
  auto copy = [](hid_t native) { return Handle(H5Tcopy(native), H5Tclose); };
  if (type_class == H5T_INTEGER) {
    const bool is_signed = H5Tget_sign(file_type) == H5T_SGN_2;
    if (size == 1 && !is_signed) return {SampleType::UInt8, copy(H5T_NATIVE_UINT8), "u8"};
    if (size == 2 && !is_signed) return {SampleType::UInt16, copy(H5T_NATIVE_UINT16), "u16"};
    if (size == 2 && is_signed) return {SampleType::Int16, copy(H5T_NATIVE_INT16), "i16"};
    throw Error(ErrorClass::InvalidArgument, context + ": unsupported sample type " +
                                                 std::string(is_signed ? "i" : "u") + std::to_string(8 * size) +
                                                 " (supported: u8, u16, i16, f16, f32, f64)");
  }
  if (type_class == H5T_FLOAT) {
    if (size == 2) {
      if (!is_ieee_half(file_type))
        throw Error(ErrorClass::InvalidArgument,
                    context + ": unsupported 16-bit float layout (only IEEE 754 binary16 is supported)");
      return {SampleType::Float16, make_half_type(), "f16"};
    }
    if (size == 4) return {SampleType::Float32, copy(H5T_NATIVE_FLOAT), "f32"};
    if (size == 8) return {SampleType::Float32, copy(H5T_NATIVE_FLOAT), "f64", true};
    throw Error(ErrorClass::InvalidArgument, context + ": unsupported sample type f" + std::to_string(8 * size) +
                                                 " (supported: u8, u16, i16, f16, f32, f64)");
  }
  throw Error(ErrorClass::InvalidArgument, context + ": samples are not numbers (HDF5 type class " +
                                               std::to_string(type_class) +
                                               "); supported: u8, u16, i16, f16, f32, f64");
}

// Every dataset of rank 3 in the file, as "/path (shape z x y x x)", for the
// message when the asked-for dataset does not exist.
std::string list_3d_datasets(hid_t file) {
  std::vector<std::string> found;
  H5Lvisit(
      file, H5_INDEX_NAME, H5_ITER_INC,
      [](hid_t group, const char* name, const H5L_info_t*, void* out) -> herr_t {
        Handle object(H5Oopen(group, name, H5P_DEFAULT), H5Oclose);
        if (!object.valid() || H5Iget_type(object.get()) != H5I_DATASET) return 0;
        Handle space(H5Dget_space(object.get()), H5Sclose);
        hsize_t shape[3];
        if (H5Sget_simple_extent_ndims(space.get()) != 3) return 0;
        H5Sget_simple_extent_dims(space.get(), shape, nullptr);
        auto& list = *static_cast<std::vector<std::string>*>(out);
        list.push_back("/" + std::string(name) + " (shape " + std::to_string(shape[0]) + "x" +
                       std::to_string(shape[1]) + "x" + std::to_string(shape[2]) + ")");
        return list.size() >= 50 ? 1 : 0;  // enough to guide the user
      },
      &found);
  if (found.empty()) return "the file holds no 3-D dataset";
  std::string text = "3-D datasets in the file: ";
  for (std::size_t i = 0; i < found.size(); ++i) text += (i ? ", " : "") + found[i];
  return text;
}

bool attribute_exists(hid_t object, const char* name) { return H5Aexists(object, name) > 0; }

// A numeric attribute of 1 or 3 values as doubles (HDF5 converts the type).
std::vector<double> read_numbers(hid_t object, const char* name, const std::string& context) {
  Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  Handle type(H5Aget_type(attribute.get()), H5Tclose);
  const H5T_class_t type_class = H5Tget_class(type.get());
  if (type_class != H5T_FLOAT && type_class != H5T_INTEGER)
    throw Error(ErrorClass::Malformed, context + ": attribute " + name + " is not numeric");
  Handle space(H5Aget_space(attribute.get()), H5Sclose);
  const hssize_t count = H5Sget_simple_extent_npoints(space.get());
  if (count != 1 && count != 3)
    throw Error(ErrorClass::Malformed,
                context + ": attribute " + name + " has " + std::to_string(count) + " values; expected 1 or 3");
  std::vector<double> values(static_cast<std::size_t>(count));
  if (H5Aread(attribute.get(), H5T_NATIVE_DOUBLE, values.data()) < 0)
    throw Error(ErrorClass::Malformed, context + ": cannot read attribute " + name + hdf5_reason());
  return values;
}

std::string read_string(hid_t object, const char* name, const std::string& context) {
  Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  Handle type(H5Aget_type(attribute.get()), H5Tclose);
  if (H5Tget_class(type.get()) != H5T_STRING)
    throw Error(ErrorClass::Malformed, context + ": attribute " + name + " is not a string");
  if (H5Tis_variable_str(type.get()) > 0) {
    Handle memory_type(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(memory_type.get(), H5T_VARIABLE);
    H5Tset_cset(memory_type.get(), H5Tget_cset(type.get()));
    char* text = nullptr;
    if (H5Aread(attribute.get(), memory_type.get(), &text) < 0 || !text)
      throw Error(ErrorClass::Malformed, context + ": cannot read attribute " + name + hdf5_reason());
    std::string value(text);
    H5free_memory(text);
    return value;
  }
  const std::size_t size = H5Tget_size(type.get());
  std::vector<char> buffer(size + 1, '\0');
  if (H5Aread(attribute.get(), type.get(), buffer.data()) < 0)
    throw Error(ErrorClass::Malformed, context + ": cannot read attribute " + name + hdf5_reason());
  return std::string(buffer.data());  // fixed-length strings may be NUL-padded
}

// voxel_size / pixel_size / origin / unit, as documented in the header.
void read_geometry(hid_t dataset, const std::string& context, DenseVolume& volume) {
  const char* size_name = attribute_exists(dataset, "voxel_size")   ? "voxel_size"
                          : attribute_exists(dataset, "pixel_size") ? "pixel_size"
                                                                    : nullptr;
  if (!size_name) return;
  std::vector<double> zyx = read_numbers(dataset, size_name, context);
  if (zyx.size() == 1) zyx.assign(3, zyx[0]);
  for (double s : zyx)
    if (!(s > 0) || !std::isfinite(s))
      throw Error(ErrorClass::Malformed, context + ": attribute " + size_name + " must be positive and finite");
  volume.voxel_size = {zyx[2], zyx[1], zyx[0]};
  if (attribute_exists(dataset, "origin")) {
    const std::vector<double> origin = read_numbers(dataset, "origin", context);
    if (origin.size() != 3) throw Error(ErrorClass::Malformed, context + ": attribute origin needs 3 values (z, y, x)");
    volume.origin = {origin[2], origin[1], origin[0]};
  }
  for (const char* unit_name : {"unit", "units"})
    if (attribute_exists(dataset, unit_name)) {
      volume.unit = read_string(dataset, unit_name, context);
      break;
    }
  volume.has_geometry = true;
}

void describe_layout(hid_t dataset, Hdf5SourceInfo& source) {
  Handle plist(H5Dget_create_plist(dataset), H5Pclose);
  source.chunked = H5Pget_layout(plist.get()) == H5D_CHUNKED;
  if (source.chunked) {
    hsize_t chunk[3] = {0, 0, 0};
    H5Pget_chunk(plist.get(), 3, chunk);
    source.chunk = {chunk[0], chunk[1], chunk[2]};
  }
  source.filters.clear();
  const int filter_count = H5Pget_nfilters(plist.get());
  for (int i = 0; i < filter_count; ++i) {
    unsigned flags = 0;
    std::size_t value_count = 0;
    char name[64] = {};
    H5Pget_filter2(plist.get(), static_cast<unsigned>(i), &flags, &value_count, nullptr, sizeof name, name, nullptr);
    source.filters += (i ? "," : "") + std::string(name);
  }
}

// Names a filter the dataset needs but this HDF5 library lacks (for example
// a plugin such as Blosc or LZ4 that is not installed), before H5Dread fails
// with a less helpful message.
void require_filters(hid_t dataset, const std::string& context) {
  Handle plist(H5Dget_create_plist(dataset), H5Pclose);
  const int filter_count = H5Pget_nfilters(plist.get());
  for (int i = 0; i < filter_count; ++i) {
    unsigned flags = 0;
    std::size_t value_count = 0;
    char name[64] = {};
    const H5Z_filter_t id = H5Pget_filter2(plist.get(), static_cast<unsigned>(i), &flags, &value_count, nullptr,
                                           sizeof name, name, nullptr);
    if (H5Zfilter_avail(id) <= 0)
      throw Error(ErrorClass::InvalidArgument, context + ": compressed with HDF5 filter " + std::to_string(id) + " (" +
                                                   name + "), which this HDF5 library does not have");
  }
}

}  // namespace

DenseVolume read_hdf5(const std::string& path, const std::string& dataset_name, Hdf5SourceInfo* source) {
  QuietHdf5Errors quiet;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(ErrorClass::Io, path + ": cannot open: no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(ErrorClass::Malformed, path + ": not an HDF5 file");
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw Error(ErrorClass::Io, path + ": cannot open the HDF5 file" + hdf5_reason());

  const std::string context = where(path, dataset_name);
  Handle dataset(H5Dopen2(file.get(), dataset_name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dataset.valid())
    throw Error(ErrorClass::InvalidArgument,
                context + " does not exist or is not a dataset; " + list_3d_datasets(file.get()));

  Handle space(H5Dget_space(dataset.get()), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank != 3)
    throw Error(ErrorClass::InvalidArgument,
                context + " is " + std::to_string(rank) + "-D; a volume needs a 3-D dataset (z, y, x)");
  hsize_t shape[3];
  H5Sget_simple_extent_dims(space.get(), shape, nullptr);
  for (hsize_t extent : shape) {
    if (extent == 0) throw Error(ErrorClass::InvalidArgument, context + " is empty");
    if (extent > std::numeric_limits<std::uint32_t>::max())
      throw Error(ErrorClass::InvalidArgument, context + ": an extent exceeds 2^32 - 1 voxels");
  }

  Handle file_type(H5Dget_type(dataset.get()), H5Tclose);
  SampleMapping mapping = map_sample_type(file_type.get(), context);
  require_filters(dataset.get(), context);

  DenseVolume volume = make_dense({static_cast<std::uint32_t>(shape[2]), static_cast<std::uint32_t>(shape[1]),
                                   static_cast<std::uint32_t>(shape[0])},
                                  mapping.sample);
  if (H5Dread(dataset.get(), mapping.memory_type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, volume.data.data()) < 0)
    throw Error(ErrorClass::Malformed, context + ": cannot read the samples" + hdf5_reason());
  read_geometry(dataset.get(), context, volume);

  if (source) {
    source->stored_type = mapping.stored_name;
    source->narrowed_to_f32 = mapping.narrowed;
    describe_layout(dataset.get(), *source);
  }
  return volume;
}

namespace {

// Samples are stored little-endian whatever the host, as most HDF5 files are.
Handle file_type_for(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
      return Handle(H5Tcopy(H5T_STD_U8LE), H5Tclose);
    case SampleType::UInt16:
      return Handle(H5Tcopy(H5T_STD_U16LE), H5Tclose);
    case SampleType::Int16:
      return Handle(H5Tcopy(H5T_STD_I16LE), H5Tclose);
    case SampleType::Float16: {
      Handle half(H5Tcopy(H5T_IEEE_F32LE), H5Tclose);
      H5Tset_fields(half.get(), 15, 10, 5, 0, 10);
      H5Tset_size(half.get(), 2);
      H5Tset_ebias(half.get(), 15);
      return half;
    }
    case SampleType::Float32:
      return Handle(H5Tcopy(H5T_IEEE_F32LE), H5Tclose);
  }
  return Handle();
}

Handle memory_type_for(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
      return Handle(H5Tcopy(H5T_NATIVE_UINT8), H5Tclose);
    case SampleType::UInt16:
      return Handle(H5Tcopy(H5T_NATIVE_UINT16), H5Tclose);
    case SampleType::Int16:
      return Handle(H5Tcopy(H5T_NATIVE_INT16), H5Tclose);
    case SampleType::Float16:
      return make_half_type();
    case SampleType::Float32:
      return Handle(H5Tcopy(H5T_NATIVE_FLOAT), H5Tclose);
  }
  return Handle();
}

void write_numbers(hid_t object, const char* name, const std::array<double, 3>& values, const std::string& context) {
  const hsize_t count = 3;
  Handle space(H5Screate_simple(1, &count, nullptr), H5Sclose);
  Handle attribute(H5Acreate2(object, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attribute.valid() || H5Awrite(attribute.get(), H5T_NATIVE_DOUBLE, values.data()) < 0)
    throw Error(ErrorClass::Io, context + ": cannot write attribute " + name + hdf5_reason());
}

void write_string(hid_t object, const char* name, const std::string& value, const std::string& context) {
  // Variable-length UTF-8: h5py reads it as str, h5dump prints it plainly.
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), H5T_VARIABLE);
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attribute(H5Acreate2(object, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  const char* text = value.c_str();
  if (!attribute.valid() || H5Awrite(attribute.get(), type.get(), &text) < 0)
    throw Error(ErrorClass::Io, context + ": cannot write attribute " + name + hdf5_reason());
}

}  // namespace

void write_hdf5(const DenseVolume& volume, const std::string& path, const std::string& dataset_name,
                int deflate_level) {
  const std::string context = where(path, dataset_name);
  if (dataset_name.empty() || dataset_name.back() == '/')
    throw Error(ErrorClass::InvalidArgument, context + ": the dataset needs a name");
  if (deflate_level < 0 || deflate_level > 9)
    throw Error(ErrorClass::InvalidArgument, context + ": deflate level must be 0 to 9");
  for (std::uint32_t extent : volume.dims)
    if (extent == 0) throw Error(ErrorClass::InvalidArgument, context + ": the volume is empty");
  if (volume.data.size() != volume.voxel_count() * sample_size(volume.type))
    throw Error(ErrorClass::InvalidArgument, context + ": the volume's data size does not match its dimensions");

  QuietHdf5Errors quiet;
  StagedFile staged(path);
  {
    Handle file(H5Fcreate(staged.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) throw Error(ErrorClass::Io, path + ": cannot create the HDF5 file" + hdf5_reason());

    const hsize_t shape[3] = {volume.dims[2], volume.dims[1], volume.dims[0]};
    Handle space(H5Screate_simple(3, shape, nullptr), H5Sclose);
    Handle link_plist(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
    H5Pset_create_intermediate_group(link_plist.get(), 1);
    Handle create_plist(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    const hsize_t chunk[3] = {std::min<hsize_t>(64, shape[0]), std::min<hsize_t>(64, shape[1]),
                              std::min<hsize_t>(64, shape[2])};
    H5Pset_chunk(create_plist.get(), 3, chunk);
    if (deflate_level > 0) {
      if (H5Zfilter_avail(H5Z_FILTER_DEFLATE) <= 0)
        throw Error(ErrorClass::InvalidArgument, context + ": this HDF5 library has no deflate filter");
      // Shuffle groups the bytes of equal significance, which deflate then
      // compresses far better for 16- and 32-bit samples.
      H5Pset_shuffle(create_plist.get());
      H5Pset_deflate(create_plist.get(), static_cast<unsigned>(deflate_level));
    }
    Handle file_type = file_type_for(volume.type);
    Handle dataset(H5Dcreate2(file.get(), dataset_name.c_str(), file_type.get(), space.get(), link_plist.get(),
                              create_plist.get(), H5P_DEFAULT),
                   H5Dclose);
    if (!dataset.valid()) throw Error(ErrorClass::Io, context + ": cannot create the dataset" + hdf5_reason());
    Handle memory_type = memory_type_for(volume.type);
    if (H5Dwrite(dataset.get(), memory_type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, volume.data.data()) < 0)
      throw Error(ErrorClass::Io, context + ": cannot write the samples" + hdf5_reason());
    if (volume.has_geometry) {
      const auto& s = volume.voxel_size;
      const auto& o = volume.origin;
      write_numbers(dataset.get(), "voxel_size", {s[2], s[1], s[0]}, context);  // dataset axis order (z, y, x)
      write_numbers(dataset.get(), "origin", {o[2], o[1], o[0]}, context);
      write_string(dataset.get(), "unit", volume.unit, context);
    }
    dataset.reset();
    if (H5Fclose(file.release()) < 0)
      throw Error(ErrorClass::Io, path + ": cannot finish the HDF5 file" + hdf5_reason());
  }
  staged.commit();
}

}  // namespace ivol::convert
