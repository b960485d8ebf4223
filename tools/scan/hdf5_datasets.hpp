// Opening and reading the numeric datasets of a projection file in HDF5,
// shared by the DXchange and NXtomo readers (projection_hdf5.cpp,
// projection_nxtomo.cpp). Internal to tools/scan; runs in the HDF5 child
// process (isolated_worker.hpp).
#pragma once

#include <hdf5.h>

#include <string>
#include <vector>

#include "hdf5_support.hpp"
#include "ivol/error.hpp"

namespace ivol::convert::hdf5 {

// True when every link of an absolute path exists (H5Lexists needs the
// parents to exist).
inline bool exists(hid_t file, const std::string& path) {
  for (std::size_t slash = path.find('/', 1);; slash = path.find('/', slash + 1)) {
    const std::string prefix = path.substr(0, slash);
    if (H5Lexists(file, prefix.c_str(), H5P_DEFAULT) <= 0) return false;
    if (slash == std::string::npos) return true;
  }
}

// An open numeric dataset and its shape.
struct Dataset {
  Handle id;
  Handle space;
  std::vector<hsize_t> shape;
};

inline Dataset open_dataset(hid_t file, const std::string& path, const std::string& name) {
  const std::string where = path + ": dataset " + name;
  Dataset d;
  const Handle access = access_caching_one_image(file, name.c_str());
  d.id = Handle(H5Dopen2(file, name.c_str(), access.get()), H5Dclose);
  if (!d.id.valid()) throw Error(ErrorClass::Malformed, where + " cannot be opened" + reason());
  Handle type(H5Dget_type(d.id.get()), H5Tclose);
  const H5T_class_t type_class = H5Tget_class(type.get());
  if (type_class != H5T_INTEGER && type_class != H5T_FLOAT)
    throw Error(ErrorClass::InvalidArgument, where + ": samples are not integers or floating-point numbers");
  d.space = Handle(H5Dget_space(d.id.get()), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(d.space.get());
  if (rank < 0 || rank > 8) throw Error(ErrorClass::Malformed, where + ": unreadable shape" + reason());
  d.shape.resize(static_cast<std::size_t>(rank));
  H5Sget_simple_extent_dims(d.space.get(), d.shape.data(), nullptr);
  return d;
}

inline std::string shape_text(const std::vector<hsize_t>& shape) {
  std::string text = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) text += (i ? ", " : "") + std::to_string(shape[i]);
  return text + ")";
}

// A failed read: a refused allocation (a small dataset in one huge
// compressed chunk, beyond the child's address-space limit) is a limit, not
// a damaged file.
[[noreturn]] inline void read_failed(const std::string& where) {
  throw Error(out_of_memory() ? ErrorClass::LimitExceeded : ErrorClass::Malformed, where + ": cannot read" + reason());
}

// Reads a box of a dataset (start and count per axis) as doubles.
inline void read_box(const Dataset& d, const std::vector<hsize_t>& start, const std::vector<hsize_t>& count,
                     double* out, const std::string& where) {
  H5Sselect_hyperslab(d.space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr);
  Handle memory(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr), H5Sclose);
  // libhdf5 1.10 zeroes its type-conversion buffer (1 MiB by default) on
  // every read that converts: sized to the request when that is smaller, a
  // read of a few rows no longer costs a megabyte of memset.
  hsize_t values = 1;
  for (const hsize_t n : count) values *= n;
  Handle transfer(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  constexpr hsize_t kDefaultBuffer = hsize_t{1} << 20;
  if (transfer.valid() && values > 0 && values * sizeof(double) < kDefaultBuffer)
    H5Pset_buffer(transfer.get(), static_cast<std::size_t>(values * sizeof(double)), nullptr, nullptr);
  if (H5Dread(d.id.get(), H5T_NATIVE_DOUBLE, memory.get(), d.space.get(),
              transfer.valid() ? transfer.get() : H5P_DEFAULT, out) < 0)
    read_failed(where);
}

// All values of a dataset of at most `most` values, as doubles.
inline std::vector<double> read_all(const Dataset& d, const std::string& where, hssize_t most) {
  const hssize_t count = H5Sget_simple_extent_npoints(d.space.get());
  if (count < 0 || count > most)
    throw Error(ErrorClass::InvalidArgument, where + " holds " + std::to_string(count) + " values, more than the " +
                                                 std::to_string(most) + " expected");
  std::vector<double> values(static_cast<std::size_t>(count));
  if (count > 0 && H5Dread(d.id.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
    read_failed(where);
  return values;
}

}  // namespace ivol::convert::hdf5
