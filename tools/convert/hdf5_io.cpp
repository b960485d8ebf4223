#include "hdf5_io.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <utility>
#include <vector>

#include "hdf5_support.hpp"
#include "sizes.hpp"
#include "ivol/error.hpp"
#include "staged_file.hpp"
#include "volume_metadata.hpp"

namespace ivol::convert {
namespace {

using hdf5::Handle;
using QuietHdf5Errors = hdf5::QuietErrors;
std::string hdf5_reason() { return hdf5::reason(); }

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

// DXchange keeps the pixel size on the sample plane with the detector:
// /measurement/instrument/detector/actual_pixel_size_x (and _y), with a
// "units" attribute, metres without one (DXchange's rule for lengths).
bool read_dxchange_pixel_size(hid_t file, const std::string& context, DenseVolume& volume) {
  const char* group = "/measurement/instrument/detector";
  const std::string x_name = std::string(group) + "/actual_pixel_size_x";
  const std::string y_name = std::string(group) + "/actual_pixel_size_y";
  auto exists = [&](const std::string& name) {
    return H5Lexists(file, "/measurement", H5P_DEFAULT) > 0 &&
           H5Lexists(file, "/measurement/instrument", H5P_DEFAULT) > 0 && H5Lexists(file, group, H5P_DEFAULT) > 0 &&
           H5Lexists(file, name.c_str(), H5P_DEFAULT) > 0;
  };
  if (!exists(x_name)) return false;
  auto read_length = [&](const std::string& name, std::string& unit) {
    const std::string where = context + ": " + name;
    Handle dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
    if (!dataset.valid()) throw Error(ErrorClass::Malformed, where + ": not a dataset");
    Handle space(H5Dget_space(dataset.get()), H5Sclose);
    Handle type(H5Dget_type(dataset.get()), H5Tclose);
    const H5T_class_t type_class = H5Tget_class(type.get());
    if ((type_class != H5T_FLOAT && type_class != H5T_INTEGER) || H5Sget_simple_extent_npoints(space.get()) != 1)
      throw Error(ErrorClass::Malformed, where + ": not a single number");
    double value = 0;
    if (H5Dread(dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &value) < 0)
      throw Error(ErrorClass::Malformed, where + ": cannot read" + hdf5_reason());
    unit = "m";
    for (const char* unit_name : {"units", "unit"})
      if (attribute_exists(dataset.get(), unit_name)) {
        unit = read_string(dataset.get(), unit_name, where);
        break;
      }
    const double factor = length_unit_factor(normalise_length_unit(unit), "mm");
    if (!(factor > 0))
      throw Error(ErrorClass::Malformed, where + ": unit '" + unit + "' is not a length unit ivol knows");
    const double mm = value * factor;
    if (!(mm > 0) || !std::isfinite(mm)) throw Error(ErrorClass::Malformed, where + ": must be positive and finite");
    return mm;
  };
  std::string x_unit, y_unit;
  const double x = read_length(x_name, x_unit);
  const double z = exists(y_name) ? read_length(y_name, y_unit) : x;
  // A reconstruction's slices lie across the rotation axis: x and y both
  // come from the detector's horizontal pixel, z from its vertical one.
  volume.voxel_size = {x, x, z};
  volume.unit = "mm";
  volume.has_geometry = true;
  volume.voxel_size_from = "DXchange " + x_name + (exists(y_name) ? " and _y" : " (z taken as x)") + ", in " + x_unit +
                           (x_unit == "m" ? " (no units attribute: DXchange's metres)" : "");
  volume.unit_from = "DXchange pixel size, converted to mm";
  return true;
}

// voxel_size / pixel_size / origin / unit / quantity / value_unit /
// provenance, as documented in the header.
bool read_itk_geometry(hid_t file, const std::string& dataset_name, const std::string& context, DenseVolume& volume);

void read_geometry(hid_t file, hid_t dataset, const std::string& dataset_name, const std::string& context,
                   DenseVolume& volume) {
  if (attribute_exists(dataset, "quantity")) volume.quantity = read_string(dataset, "quantity", context);
  if (attribute_exists(dataset, "value_unit")) volume.value_unit = read_string(dataset, "value_unit", context);
  if (!volume.quantity.empty() || !volume.value_unit.empty())
    volume.quantity_from = "HDF5 attributes quantity, value_unit";
  if (attribute_exists(dataset, "provenance")) volume.provenance = read_string(dataset, "provenance", context);
  if (read_itk_geometry(file, dataset_name, context, volume)) return;
  const char* size_name = attribute_exists(dataset, "voxel_size")   ? "voxel_size"
                          : attribute_exists(dataset, "pixel_size") ? "pixel_size"
                                                                    : nullptr;
  if (!size_name) {
    read_dxchange_pixel_size(file, context, volume);
    return;
  }
  std::vector<double> zyx = read_numbers(dataset, size_name, context);
  if (zyx.size() == 1) zyx.assign(3, zyx[0]);
  for (double s : zyx)
    if (!(s > 0) || !std::isfinite(s))
      throw Error(ErrorClass::Malformed, context + ": attribute " + size_name + " must be positive and finite");
  volume.voxel_size = {zyx[2], zyx[1], zyx[0]};
  volume.voxel_size_from = std::string("HDF5 attribute ") + size_name;
  if (attribute_exists(dataset, "origin")) {
    const std::vector<double> origin = read_numbers(dataset, "origin", context);
    if (origin.size() != 3) throw Error(ErrorClass::Malformed, context + ": attribute origin needs 3 values (z, y, x)");
    volume.origin = {origin[2], origin[1], origin[0]};
    volume.origin_from = "HDF5 attribute origin";
  }
  for (const char* unit_name : {"unit", "units"})
    if (attribute_exists(dataset, unit_name)) {
      volume.unit = read_string(dataset, unit_name, context);
      volume.unit_from = std::string("HDF5 attribute ") + unit_name;
      break;
    }
  volume.has_geometry = !voxel_size_marked_unknown(volume.provenance);
}

// Whether every group on the way to `path` and the link itself exist
// (H5Lexists fails on a missing intermediate group).
bool link_exists(hid_t file, const std::string& path) {
  for (std::size_t slash = path.find('/', 1);; slash = path.find('/', slash + 1)) {
    const std::string prefix = slash == std::string::npos ? path : path.substr(0, slash);
    if (H5Lexists(file, prefix.c_str(), H5P_DEFAULT) <= 0) return false;
    if (slash == std::string::npos) return true;
  }
}

constexpr const char* kItkVoxelData = "/ITKImage/0/VoxelData";

// ITK's HDF5ImageIO keeps the image's geometry in datasets beside its
// VoxelData: Spacing and Origin (x, y, z), Directions (3 × 3). Spacing is
// in ITK's millimetres; a rotated or flipped image is refused, as for
// MetaImage (ivol stores axis-aligned grids).
bool read_itk_geometry(hid_t file, const std::string& dataset_name, const std::string& context, DenseVolume& volume) {
  const std::string suffix = "/VoxelData";
  if (dataset_name.size() <= suffix.size() ||
      dataset_name.compare(dataset_name.size() - suffix.size(), suffix.size(), suffix) != 0)
    return false;
  const std::string group = dataset_name.substr(0, dataset_name.size() - suffix.size());
  if (!link_exists(file, group + "/Spacing")) return false;
  auto read_vector = [&](const std::string& name, std::size_t count) {
    const std::string where = context + ": " + name;
    Handle dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
    if (!dataset.valid()) throw Error(ErrorClass::Malformed, where + ": not a dataset");
    Handle space(H5Dget_space(dataset.get()), H5Sclose);
    Handle type(H5Dget_type(dataset.get()), H5Tclose);
    const H5T_class_t type_class = H5Tget_class(type.get());
    if ((type_class != H5T_FLOAT && type_class != H5T_INTEGER) ||
        H5Sget_simple_extent_npoints(space.get()) != static_cast<hssize_t>(count))
      throw Error(ErrorClass::Malformed, where + ": needs " + std::to_string(count) + " numbers");
    std::vector<double> values(count);
    if (H5Dread(dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
      throw Error(ErrorClass::Malformed, where + ": cannot read" + hdf5_reason());
    for (double v : values)
      if (!std::isfinite(v)) throw Error(ErrorClass::Malformed, where + ": not finite");
    return values;
  };
  const std::vector<double> spacing = read_vector(group + "/Spacing", 3);
  for (double v : spacing)
    if (!(v > 0)) throw Error(ErrorClass::Malformed, context + ": " + group + "/Spacing must be positive");
  if (link_exists(file, group + "/Directions")) {
    const std::vector<double> m = read_vector(group + "/Directions", 9);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        if (std::abs(m[static_cast<std::size_t>(r * 3 + c)] - (r == c ? 1.0 : 0.0)) > 1e-9)
          throw Error(ErrorClass::InvalidArgument,
                      context + ": " + group +
                          "/Directions is not the identity: ivol stores axis-aligned grids, and a rotated or flipped "
                          "image cannot be kept without resampling (resample it to the identity direction first)");
  }
  volume.voxel_size = {spacing[0], spacing[1], spacing[2]};
  volume.voxel_size_from = "ITK HDF5 " + group + "/Spacing";
  if (link_exists(file, group + "/Origin")) {
    const std::vector<double> origin = read_vector(group + "/Origin", 3);
    volume.origin = {origin[0], origin[1], origin[2]};
    volume.origin_from = "ITK HDF5 " + group + "/Origin";
  }
  volume.unit = "mm";
  volume.unit_from = "ITK's convention (its HDF5 images have no unit)";
  volume.has_geometry = true;
  return true;
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

namespace {

// What the reader may allocate when given no budget: the child's default
// (kDefaultChildMemory of tools/isolated).
constexpr std::uint64_t kReaderMemoryWithoutBudget = std::uint64_t{1} << 30;

// Reads a dataset slab by slab with hyperslab selections.
class Hdf5SlabReader final : public SlabReader {
 public:
  Hdf5SlabReader(const std::string& path, const std::string& requested, Hdf5SourceInfo* source,
                 std::uint64_t memory_bytes) {
    QuietHdf5Errors quiet;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) throw Error(ErrorClass::Io, path + ": cannot open: no such file");
    if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(ErrorClass::Malformed, path + ": not an HDF5 file");
    file_ = Handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (!file_.valid()) throw Error(ErrorClass::Io, path + ": cannot open the HDF5 file" + hdf5_reason());
    // The default name, absent, in a file ITK wrote: ITK's image is meant.
    dataset_name_ = requested;
    if (requested == kDefaultDataset && !link_exists(file_.get(), requested) && link_exists(file_.get(), kItkVoxelData))
      dataset_name_ = kItkVoxelData;
    const std::string& dataset_name = dataset_name_;
    context_ = where(path, dataset_name);
    const Handle access = hdf5::access_caching_one_image(
        file_.get(), dataset_name.c_str(),
        static_cast<std::size_t>((memory_bytes ? memory_bytes : kReaderMemoryWithoutBudget) / 4));
    dataset_ = Handle(H5Dopen2(file_.get(), dataset_name.c_str(), access.get()), H5Dclose);
    if (!dataset_.valid())
      throw Error(ErrorClass::InvalidArgument,
                  context_ + " does not exist or is not a dataset; " + list_3d_datasets(file_.get()));
    space_ = Handle(H5Dget_space(dataset_.get()), H5Sclose);
    const int rank = H5Sget_simple_extent_ndims(space_.get());
    if (rank != 3)
      throw Error(ErrorClass::InvalidArgument,
                  context_ + " is " + std::to_string(rank) + "-D; a volume needs a 3-D dataset (z, y, x)");
    hsize_t shape[3];
    H5Sget_simple_extent_dims(space_.get(), shape, nullptr);
    for (hsize_t extent : shape) {
      if (extent == 0) throw Error(ErrorClass::InvalidArgument, context_ + " is empty");
      if (extent > std::numeric_limits<std::uint32_t>::max())
        throw Error(ErrorClass::InvalidArgument, context_ + ": an extent exceeds 2^32 - 1 voxels");
    }
    Handle file_type(H5Dget_type(dataset_.get()), H5Tclose);
    mapping_ = map_sample_type(file_type.get(), context_);
    require_filters(dataset_.get(), context_);
    require_chunk_within(memory_bytes ? memory_bytes : kReaderMemoryWithoutBudget, file_type.get());
    shape_.dims = {static_cast<std::uint32_t>(shape[2]), static_cast<std::uint32_t>(shape[1]),
                   static_cast<std::uint32_t>(shape[0])};
    shape_.type = mapping_.sample;
    read_geometry(file_.get(), dataset_.get(), dataset_name_, context_, shape_);
    if (source) {
      source->dataset = dataset_name;
      source->stored_type = mapping_.stored_name;
      source->narrowed_to_f32 = mapping_.narrowed;
      describe_layout(dataset_.get(), *source);
    }
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    read_box({z0, 0, 0}, {count, shape_.dims[1], shape_.dims[0]}, out,
             "slices " + std::to_string(z0) + " .. " + std::to_string(z0 + count));
  }

  // A hyperslab of whole rows of one slice. Chunks that reach past the band
  // (taller, or deeper than one slice) are inflated again for the next band
  // or slice unless the chunk cache still holds them: slower, never more
  // memory than the cache and one chunk.
  bool reads_rows() const override { return true; }
  void read_rows(std::uint32_t z, std::uint32_t y0, std::uint32_t rows, void* out) override {
    read_box({z, y0, 0}, {1, rows, shape_.dims[0]}, out,
             "slice " + std::to_string(z) + " rows " + std::to_string(y0) + " .. " + std::to_string(y0 + rows));
  }

 private:
  std::string dataset_name_;
  std::string context_;
  Handle file_;
  Handle dataset_;
  Handle space_;
  SampleMapping mapping_;

  // libhdf5 inflates a filtered chunk whole, whatever part of it is read,
  // with the stored chunk beside it (at worst as large): a chunk beyond what
  // the process may allocate is refused by its size before the read that
  // would fail (a 4x4x4 dataset in one 2 GiB gzip chunk; a 16384^2 slice in
  // one chunk under --memory 16). Unfiltered chunks are read in place.
  void require_chunk_within(std::uint64_t allowance, hid_t file_type) const {
    Handle plist(H5Dget_create_plist(dataset_.get()), H5Pclose);
    if (H5Pget_layout(plist.get()) != H5D_CHUNKED || H5Pget_nfilters(plist.get()) <= 0) return;
    hsize_t chunk[3] = {0, 0, 0};
    if (H5Pget_chunk(plist.get(), 3, chunk) != 3) return;
    const double bytes = static_cast<double>(chunk[0]) * static_cast<double>(chunk[1]) *
                         static_cast<double>(chunk[2]) * static_cast<double>(H5Tget_size(file_type));
    if (2 * bytes <= static_cast<double>(allowance)) return;
    throw Error(ErrorClass::LimitExceeded,
                context_ + ": a chunk of " + std::to_string(chunk[0]) + "x" + std::to_string(chunk[1]) + "x" +
                    std::to_string(chunk[2]) + " (z, y, x) is " + mib_text(bytes) +
                    " inflated, and libhdf5 inflates a chunk whole beside the stored one: more than the " +
                    mib_text(allowance) + " its process may allocate (" +
                    memory_option_for(static_cast<std::uint64_t>(std::min(2 * bytes, 1.8e19))) + " allows it)");
  }

  // start and extent in the dataset's axis order (z, y, x).
  void read_box(const std::array<hsize_t, 3>& start, const std::array<hsize_t, 3>& extent, void* out,
                const std::string& what) {
    QuietHdf5Errors quiet;
    H5Sselect_hyperslab(space_.get(), H5S_SELECT_SET, start.data(), nullptr, extent.data(), nullptr);
    Handle memory(H5Screate_simple(3, extent.data(), nullptr), H5Sclose);
    if (H5Dread(dataset_.get(), mapping_.memory_type.get(), memory.get(), space_.get(), H5P_DEFAULT, out) < 0)
      throw Error(hdf5::out_of_memory() ? ErrorClass::LimitExceeded : ErrorClass::Malformed,
                  context_ + ": cannot read " + what + hdf5_reason());
  }
};

}  // namespace

std::unique_ptr<SlabReader> open_hdf5_slabs_in_process(const std::string& path, const std::string& dataset,
                                                       Hdf5SourceInfo* source, std::uint64_t memory_bytes) {
  return std::make_unique<Hdf5SlabReader>(path, dataset, source, memory_bytes);
}

DenseVolume read_hdf5(const std::string& path, const std::string& dataset_name, Hdf5SourceInfo* source) {
  auto reader = open_hdf5_slabs(path, dataset_name, source);
  DenseVolume volume = shape_of(reader->shape());
  volume.data.resize(volume.voxel_count() * sample_size(volume.type));
  reader->read(0, volume.dims[2], volume.data.data());
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

// Writes a dataset slab by slab (hyperslab writes) into a staged file.
class Hdf5SlabWriter final : public SlabWriter {
 public:
  Hdf5SlabWriter(const std::string& path, const DenseVolume& shape, const std::string& dataset_name, int deflate_level,
                 std::uint32_t band_rows)
      : path_(path), context_(where(path, dataset_name)), shape_(shape), staged_(path) {
    if (dataset_name.empty() || dataset_name.back() == '/')
      throw Error(ErrorClass::InvalidArgument, context_ + ": the dataset needs a name");
    if (deflate_level < 0 || deflate_level > 9)
      throw Error(ErrorClass::InvalidArgument, context_ + ": deflate level must be 0 to 9");
    for (std::uint32_t extent : shape.dims)
      if (extent == 0) throw Error(ErrorClass::InvalidArgument, context_ + ": the volume is empty");
    // libhdf5's exit handler closes what is still open, and on a file whose
    // flush failed (a full disk) it crashed after our error was printed.
    // Every file is closed here, so the handler has nothing to do; this
    // only takes effect before the library's first call.
    H5dont_atexit();
    QuietHdf5Errors quiet;
    file_ = Handle(H5Fcreate(staged_.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file_.valid()) throw Error(ErrorClass::Io, path + ": cannot create the HDF5 file" + hdf5_reason());
    const hsize_t extent[3] = {shape.dims[2], shape.dims[1], shape.dims[0]};
    space_ = Handle(H5Screate_simple(3, extent, nullptr), H5Sclose);
    Handle link_plist(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
    H5Pset_create_intermediate_group(link_plist.get(), 1);
    Handle create_plist(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    const hsize_t chunk[3] = {band_rows ? 1 : std::min<hsize_t>(64, extent[0]),
                              std::min<hsize_t>(band_rows ? std::min<hsize_t>(64, band_rows) : 64, extent[1]),
                              std::min<hsize_t>(64, extent[2])};
    H5Pset_chunk(create_plist.get(), 3, chunk);
    if (deflate_level > 0) {
      if (H5Zfilter_avail(H5Z_FILTER_DEFLATE) <= 0)
        throw Error(ErrorClass::InvalidArgument, context_ + ": this HDF5 library has no deflate filter");
      // Shuffle groups the bytes of equal significance, which deflate then
      // compresses far better for 16- and 32-bit samples.
      H5Pset_shuffle(create_plist.get());
      H5Pset_deflate(create_plist.get(), static_cast<unsigned>(deflate_level));
    }
    Handle file_type = file_type_for(shape.type);
    dataset_ = Handle(H5Dcreate2(file_.get(), dataset_name.c_str(), file_type.get(), space_.get(), link_plist.get(),
                                 create_plist.get(), H5P_DEFAULT),
                      H5Dclose);
    if (!dataset_.valid()) throw Error(ErrorClass::Io, context_ + ": cannot create the dataset" + hdf5_reason());
    memory_type_ = memory_type_for(shape.type);
  }

  void write(const void* samples, std::uint32_t count) override {
    QuietHdf5Errors quiet;
    const hsize_t start[3] = {at_.slices, 0, 0};
    const hsize_t extent[3] = {count, shape_.dims[1], shape_.dims[0]};
    H5Sselect_hyperslab(space_.get(), H5S_SELECT_SET, start, nullptr, extent, nullptr);
    Handle memory(H5Screate_simple(3, extent, nullptr), H5Sclose);
    if (H5Dwrite(dataset_.get(), memory_type_.get(), memory.get(), space_.get(), H5P_DEFAULT, samples) < 0)
      throw Error(ErrorClass::Io, context_ + ": cannot write the samples" + hdf5_reason());
    at_.slices += count;
  }

  // Each band a hyperslab of rows, split where a slice ends.
  bool writes_rows() const override { return true; }
  void write_rows(const void* samples, std::uint32_t rows) override {
    QuietHdf5Errors quiet;
    const auto* p = static_cast<const std::uint8_t*>(samples);
    const std::size_t row_bytes = std::size_t{shape_.dims[0]} * sample_size(shape_.type);
    while (rows > 0) {
      if (at_.slices >= shape_.dims[2])
        throw Error(ErrorClass::InvalidArgument, context_ + ": more rows than the dataset holds");
      const std::uint32_t n = std::min(rows, shape_.dims[1] - at_.rows);
      const hsize_t start[3] = {at_.slices, at_.rows, 0};
      const hsize_t extent[3] = {1, n, shape_.dims[0]};
      H5Sselect_hyperslab(space_.get(), H5S_SELECT_SET, start, nullptr, extent, nullptr);
      Handle memory(H5Screate_simple(3, extent, nullptr), H5Sclose);
      if (H5Dwrite(dataset_.get(), memory_type_.get(), memory.get(), space_.get(), H5P_DEFAULT, p) < 0)
        throw Error(ErrorClass::Io, context_ + ": cannot write the samples" + hdf5_reason());
      p += n * row_bytes;
      rows -= n;
      at_.advance(n, shape_.dims[1]);
    }
  }

  void finish() override {
    if (at_.slices != shape_.dims[2] || at_.rows != 0)
      throw Error(ErrorClass::InvalidArgument, context_ + ": " + std::to_string(at_.slices) + " of " +
                                                   std::to_string(shape_.dims[2]) + " slices written");
    QuietHdf5Errors quiet;
    if (shape_.has_geometry) {
      const auto& s = shape_.voxel_size;
      const auto& o = shape_.origin;
      write_numbers(dataset_.get(), "voxel_size", {s[2], s[1], s[0]}, context_);  // dataset axis order (z, y, x)
      write_numbers(dataset_.get(), "origin", {o[2], o[1], o[0]}, context_);
      write_string(dataset_.get(), "unit", shape_.unit, context_);
    }
    if (!shape_.quantity.empty()) write_string(dataset_.get(), "quantity", shape_.quantity, context_);
    if (!shape_.value_unit.empty()) write_string(dataset_.get(), "value_unit", shape_.value_unit, context_);
    if (!shape_.provenance.empty()) write_string(dataset_.get(), "provenance", shape_.provenance, context_);
    // Chunks are compressed and written when the dataset closes and the
    // file flushes, not in H5Dwrite: on a full disk these are the calls
    // that fail, and unchecked they gave exit 0 and a file of zeros.
    if (H5Dclose(dataset_.release()) < 0)
      throw Error(ErrorClass::Io, context_ + ": cannot write the samples" + hdf5_reason());
    space_.reset();
    if (H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0)
      throw Error(ErrorClass::Io, path_ + ": cannot write the HDF5 file" + hdf5_reason());
    if (H5Fclose(file_.release()) < 0)
      throw Error(ErrorClass::Io, path_ + ": cannot finish the HDF5 file" + hdf5_reason());
    staged_.commit();
  }

 private:
  std::string path_;
  std::string context_;
  DenseVolume shape_;
  StagedFile staged_;  // before the HDF5 handles: the file closes before it is removed
  Handle file_;
  Handle space_;
  Handle dataset_;
  Handle memory_type_;
  RowPosition at_;
};

}  // namespace

std::unique_ptr<SlabWriter> create_hdf5_slabs(const std::string& path, const DenseVolume& shape,
                                              const std::string& dataset, int deflate_level, std::uint32_t band_rows) {
  return std::make_unique<Hdf5SlabWriter>(path, shape_of(shape), dataset, deflate_level, band_rows);
}

void write_hdf5(const DenseVolume& volume, const std::string& path, const std::string& dataset_name,
                int deflate_level) {
  if (volume.data.size() != volume.voxel_count() * sample_size(volume.type))
    throw Error(ErrorClass::InvalidArgument,
                where(path, dataset_name) + ": the volume's data size does not match its dimensions");
  auto writer = create_hdf5_slabs(path, volume, dataset_name, deflate_level);
  writer->write(volume.data.data(), volume.dims[2]);
  writer->finish();
}

}  // namespace ivol::convert
