// DXchange projections in HDF5: /exchange/data read by hyperslab, flat and
// dark fields averaged, theta for the geometry; and the writer.
#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <utility>

#include "hdf5_datasets.hpp"
#include "ivol/error.hpp"
#include "projection_io.hpp"
#include "staged_file.hpp"

namespace ivol::convert {
namespace {

constexpr const char* kData = "/exchange/data";
constexpr const char* kWhite = "/exchange/data_white";
constexpr const char* kDark = "/exchange/data_dark";
constexpr const char* kTheta = "/exchange/theta";

using hdf5::Dataset;
using hdf5::exists;
using hdf5::Handle;
using hdf5::open_dataset;
using hdf5::read_box;
using hdf5::read_failed;
using hdf5::shape_text;
using QuietHdf5Errors = hdf5::QuietErrors;
std::string hdf5_reason() { return hdf5::reason(); }

// Mean over the first axis of (n, rows, columns), or the one (rows, columns)
// image.
std::vector<double> read_field(hid_t file, const std::string& path, const char* name, hsize_t rows, hsize_t columns) {
  const Dataset d = open_dataset(file, path, name);
  const std::string where = path + ": dataset " + name;
  const bool single = d.shape.size() == 2;
  if ((d.shape.size() != 3 && !single) || d.shape[d.shape.size() - 2] != rows || d.shape.back() != columns)
    throw Error(ErrorClass::InvalidArgument, where + " has shape " + shape_text(d.shape) + "; expected (n, " +
                                                 std::to_string(rows) + ", " + std::to_string(columns) + ")");
  const hsize_t images = single ? 1 : d.shape[0];
  if (images == 0) throw Error(ErrorClass::InvalidArgument, where + " holds no images");
  FieldAverage average(static_cast<std::size_t>(rows * columns));
  std::vector<double> image(static_cast<std::size_t>(rows * columns));
  for (hsize_t k = 0; k < images; ++k) {
    if (single)
      read_box(d, {0, 0}, {rows, columns}, image.data(), where);
    else
      read_box(d, {k, 0, 0}, {1, rows, columns}, image.data(), where + " image " + std::to_string(k));
    average.add(image.data());
  }
  return average.mean();
}

class DxchangeReader final : public ProjectionReader {
 public:
  DxchangeReader(const std::string& path, Handle file, Dataset data, std::string name)
      : ProjectionReader(path, static_cast<int>(data.shape[2]), static_cast<int>(data.shape[1]),
                         static_cast<std::size_t>(data.shape[0])),
        file_(std::move(file)),
        data_(std::move(data)),
        name_(std::move(name)) {}

  void enable_intensities(std::vector<double> flat, std::vector<double> dark, double minimum_signal) {
    IntensityOptions options;
    options.minimum_signal = minimum_signal;
    set_fields(std::move(flat), std::move(dark), options);
  }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    QuietHdf5Errors quiet;
    read_box(data_, {view, static_cast<hsize_t>(row_begin), 0},
             {1, static_cast<hsize_t>(row_end - row_begin), static_cast<hsize_t>(columns_)}, out,
             path_ + ": dataset " + name_ + " view " + std::to_string(view) + " rows " + std::to_string(row_begin) +
                 ".." + std::to_string(row_end));
  }

 private:
  Handle file_;
  Dataset data_;
  std::string name_;
};

}  // namespace

DxchangeProjections open_dxchange_projections_in_process(const std::string& path, const DxchangeOptions& options) {
  QuietHdf5Errors quiet;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(ErrorClass::Io, path + ": cannot open: no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(ErrorClass::Malformed, path + ": not an HDF5 file");
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw Error(ErrorClass::Io, path + ": cannot open the HDF5 file" + hdf5_reason());
  const std::string name = options.dataset.empty() ? std::string(kData) : options.dataset;
  if (!exists(file.get(), name.c_str()))
    throw Error(ErrorClass::InvalidArgument,
                path + ": dataset " + name + " is missing" +
                    (options.dataset.empty() ? " (not a DXchange file? --dataset names another)" : ""));
  Dataset data = open_dataset(file.get(), path, name.c_str());
  if (data.shape.size() != 3 || data.shape[0] == 0 || data.shape[1] == 0 || data.shape[2] == 0 ||
      data.shape[1] > std::numeric_limits<int>::max() || data.shape[2] > std::numeric_limits<int>::max())
    throw Error(ErrorClass::InvalidArgument, path + ": dataset " + name + " has shape " + shape_text(data.shape) +
                                                 "; expected (views, rows, columns), none empty");
  const hsize_t rows = data.shape[1], columns = data.shape[2], views = data.shape[0];

  std::vector<double> flat, dark;
  const bool has_white = exists(file.get(), kWhite);
  if (has_white) {
    flat = read_field(file.get(), path, kWhite, rows, columns);
    if (exists(file.get(), kDark)) dark = read_field(file.get(), path, kDark, rows, columns);
  } else if (!options.assume_line_integrals) {
    throw Error(ErrorClass::InvalidArgument,
                path + ": dataset " + kWhite +
                    " is missing: without a flat field the data cannot be turned into line integrals (if they are "
                    "line integrals already, say so)");
  }
  DxchangeProjections result;
  if (exists(file.get(), kTheta)) {
    const Dataset theta = open_dataset(file.get(), path, kTheta);
    const hssize_t count = H5Sget_simple_extent_npoints(theta.space.get());
    if (count < 0 || static_cast<hsize_t>(count) != views)
      throw Error(ErrorClass::InvalidArgument, path + ": dataset " + kTheta + " holds " + std::to_string(count) +
                                                   " angles for " + std::to_string(views) + " views");
    result.theta_deg.resize(static_cast<std::size_t>(count));
    if (H5Dread(theta.id.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, result.theta_deg.data()) < 0)
      read_failed(path + ": dataset " + kTheta);
  }

  auto reader = std::make_unique<DxchangeReader>(path, std::move(file), std::move(data), name);
  if (has_white) reader->enable_intensities(std::move(flat), std::move(dark), options.minimum_signal);
  result.projections = std::move(reader);
  return result;
}

namespace {

// A float32 dataset (created with its groups) written image by image.
Handle create_dataset(hid_t file, const char* name, hid_t type, const std::vector<hsize_t>& shape,
                      const std::string& path) {
  Handle space(H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr), H5Sclose);
  Handle links(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  H5Pset_create_intermediate_group(links.get(), 1);
  Handle d(H5Dcreate2(file, name, type, space.get(), links.get(), H5P_DEFAULT, H5P_DEFAULT), H5Dclose);
  if (!d.valid()) throw Error(ErrorClass::Io, path + ": cannot create dataset " + name + hdf5_reason());
  return d;
}

void write_image(hid_t dataset, hsize_t index, hsize_t rows, hsize_t columns, const float* values,
                 const std::string& where) {
  Handle space(H5Dget_space(dataset), H5Sclose);
  const hsize_t start[3] = {index, 0, 0};
  const hsize_t count[3] = {1, rows, columns};
  H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr);
  Handle memory(H5Screate_simple(3, count, nullptr), H5Sclose);
  if (H5Dwrite(dataset, H5T_NATIVE_FLOAT, memory.get(), space.get(), H5P_DEFAULT, values) < 0)
    throw Error(ErrorClass::Io, where + ": cannot write" + hdf5_reason());
}

}  // namespace

void write_dxchange(const std::string& path, ivol::recon::ProjectionSource& source,
                    const std::vector<double>& angles_deg, const FieldImages& fields) {
  const hsize_t views = source.view_count();
  const hsize_t rows = static_cast<hsize_t>(source.rows());
  const hsize_t columns = static_cast<hsize_t>(source.columns());
  const std::size_t pixels = static_cast<std::size_t>(rows * columns);
  if (angles_deg.size() != views)
    throw Error(ErrorClass::InvalidArgument,
                path + ": " + std::to_string(angles_deg.size()) + " angles for " + std::to_string(views) + " views");
  if ((!fields.flat.empty() && fields.flat.size() != pixels) || (!fields.dark.empty() && fields.dark.size() != pixels))
    throw Error(ErrorClass::InvalidArgument,
                path + ": flat or dark image is not " + std::to_string(rows) + "x" + std::to_string(columns));
  if (fields.flat.empty() && !fields.dark.empty())
    throw Error(ErrorClass::InvalidArgument, path + ": a dark field without a flat field");

  QuietHdf5Errors quiet;
  StagedFile staged(path);
  Handle file(H5Fcreate(staged.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw Error(ErrorClass::Io, path + ": cannot create the HDF5 file" + hdf5_reason());
  {
    Handle data = create_dataset(file.get(), kData, H5T_IEEE_F32LE, {views, rows, columns}, path);
    std::vector<float> image(pixels);
    for (hsize_t v = 0; v < views; ++v) {
      source.read_rows(static_cast<std::size_t>(v), 0, source.rows(), image.data());
      if (!fields.flat.empty())
        for (std::size_t i = 0; i < pixels; ++i) {
          const double dark = fields.dark.empty() ? 0.0 : fields.dark[i];
          image[i] = static_cast<float>(dark + (fields.flat[i] - dark) * std::exp(-static_cast<double>(image[i])));
        }
      write_image(data.get(), v, rows, columns, image.data(), path + ": dataset " + kData);
    }
    const std::pair<const char*, const std::vector<float>*> extra[] = {{kWhite, &fields.flat}, {kDark, &fields.dark}};
    for (const auto& [name, values] : extra) {
      if (values->empty()) continue;
      Handle d = create_dataset(file.get(), name, H5T_IEEE_F32LE, {1, rows, columns}, path);
      write_image(d.get(), 0, rows, columns, values->data(), path + ": dataset " + name);
    }
    Handle theta = create_dataset(file.get(), kTheta, H5T_IEEE_F64LE, {views}, path);
    if (H5Dwrite(theta.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, angles_deg.data()) < 0)
      throw Error(ErrorClass::Io, path + ": cannot write dataset " + kTheta + hdf5_reason());
  }
  if (H5Fclose(file.release()) < 0) throw Error(ErrorClass::Io, path + ": cannot finish the HDF5 file" + hdf5_reason());
  staged.commit();
}

}  // namespace ivol::convert
