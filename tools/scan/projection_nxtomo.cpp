// NeXus NXtomo projections in HDF5, read as DXchange's readers (tomopy's
// dxchange.read_nxtm and friends) read them: the frames of
// ENTRY/instrument/detector/data are sorted by ENTRY/instrument/detector/
// image_key (0 projection, 1 flat, 2 dark, 3 invalid), the flats and darks
// averaged per pixel over all their frames (before and after the scan alike),
// and the projections become line integrals −log((I − D)/(F − D)). Angles
// are ENTRY/sample/rotation_angle of the projection frames; the pixel sizes
// and distances come with their units attributes and are returned in mm.
// Which HDF5 layout a file has (NXtomo or DXchange) is decided here too, so
// that one child process opens it.
#include <hdf5.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "hdf5_datasets.hpp"
#include "projection_io.hpp"

namespace ivol::convert {
namespace {

using hdf5::Dataset;
using hdf5::exists;
using hdf5::Handle;

// Frames a file may hold: the image keys and angles are read whole.
constexpr hssize_t kMostFrames = hssize_t{1} << 24;

// A string attribute of an object, or "" when it has none.
std::string string_attribute(hid_t object, const char* name) {
  if (H5Aexists(object, name) <= 0) return {};
  Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  Handle type(H5Aget_type(attribute.get()), H5Tclose);
  if (!attribute.valid() || H5Tget_class(type.get()) != H5T_STRING) return {};
  Handle space(H5Aget_space(attribute.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) return {};
  if (H5Tis_variable_str(type.get()) > 0) {
    Handle memory(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(memory.get(), H5T_VARIABLE);
    H5Tset_cset(memory.get(), H5Tget_cset(type.get()));  // HDF5 converts neither way between ASCII and UTF-8
    char* text = nullptr;
    if (H5Aread(attribute.get(), memory.get(), &text) < 0 || !text) return {};
    std::string value(text);
    H5free_memory(text);
    return value;
  }
  const std::size_t size = H5Tget_size(type.get());
  if (size == 0 || size > 4096) return {};
  std::string value(size, '\0');
  Handle memory(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(memory.get(), size);
  H5Tset_cset(memory.get(), H5Tget_cset(type.get()));
  if (H5Aread(attribute.get(), memory.get(), value.data()) < 0) return {};
  return value.substr(0, value.find('\0'));
}

// A scalar string dataset (NXentry/definition), or "" when unreadable.
std::string string_dataset(hid_t file, const std::string& name) {
  if (!exists(file, name)) return {};
  Handle d(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  Handle type(H5Dget_type(d.get()), H5Tclose);
  if (!d.valid() || H5Tget_class(type.get()) != H5T_STRING) return {};
  Handle space(H5Dget_space(d.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) return {};
  Handle memory(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_cset(memory.get(), H5Tget_cset(type.get()));  // HDF5 converts neither way between ASCII and UTF-8
  if (H5Tis_variable_str(type.get()) > 0) {
    H5Tset_size(memory.get(), H5T_VARIABLE);
    char* text = nullptr;
    if (H5Dread(d.get(), memory.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, &text) < 0 || !text) return {};
    std::string value(text);
    H5free_memory(text);
    return value;
  }
  const std::size_t size = H5Tget_size(type.get());
  if (size == 0 || size > 4096) return {};
  std::string value(size, '\0');
  H5Tset_size(memory.get(), size);
  if (H5Dread(d.get(), memory.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, value.data()) < 0) return {};
  return value.substr(0, value.find('\0'));
}

// The top-level groups that are NXtomo entries: NX_class NXentry and a
// definition (dataset or attribute) of NXtomo.
std::vector<std::string> nxtomo_entries(hid_t file) {
  std::vector<std::string> entries;
  H5G_info_t info{};
  if (H5Gget_info(file, &info) < 0) return entries;
  for (hsize_t i = 0; i < info.nlinks && i < 4096; ++i) {
    char name[256] = {};
    if (H5Lget_name_by_idx(file, ".", H5_INDEX_NAME, H5_ITER_INC, i, name, sizeof name, H5P_DEFAULT) <= 0) continue;
    const std::string path = "/" + std::string(name);
    H5O_info_t object{};
    if (H5Oget_info_by_name(file, path.c_str(), &object, H5P_DEFAULT) < 0 || object.type != H5O_TYPE_GROUP) continue;
    Handle group(H5Gopen2(file, path.c_str(), H5P_DEFAULT), H5Gclose);
    if (!group.valid()) continue;
    std::string definition = string_dataset(file, path + "/definition");
    if (definition.empty()) definition = string_attribute(group.get(), "definition");
    if (definition == "NXtomo") entries.push_back(path);
  }
  return entries;
}

// Millimetres per unit of a length's units attribute; 0 when unknown.
double millimetres_per(const std::string& unit) {
  if (unit == "m" || unit == "meter" || unit == "metre" || unit == "meters" || unit == "metres") return 1e3;
  if (unit == "cm") return 10.0;
  if (unit == "mm" || unit == "millimeter" || unit == "millimetre") return 1.0;
  if (unit == "um" || unit == "µm" || unit == "micron" || unit == "micrometer" || unit == "micrometre") return 1e-3;
  if (unit == "nm" || unit == "nanometer" || unit == "nanometre") return 1e-6;
  return 0.0;
}

// A scalar length of the entry, in mm, with the field it came from. A file
// without a units attribute is read in metres (NeXus's SI default for
// NX_LENGTH fields), and says so in `field`.
LengthField length_field(hid_t file, const std::string& path, const std::string& name) {
  LengthField length;
  if (!exists(file, name)) return length;
  const Dataset d = hdf5::open_dataset(file, path, name);
  const std::vector<double> value = hdf5::read_all(d, path + ": dataset " + name, 1);
  if (value.size() != 1 || !std::isfinite(value[0]))
    throw Error(ErrorClass::InvalidArgument, path + ": dataset " + name + " is not one finite number");
  std::string unit = string_attribute(d.id.get(), "units");
  double scale = 1e3;
  std::string assumed;
  if (unit.empty()) {
    assumed = ", no units attribute: metres";
  } else {
    scale = millimetres_per(unit);
    if (scale == 0.0)
      throw Error(ErrorClass::InvalidArgument, path + ": dataset " + name + " has units '" + unit +
                                                   "', not a length ivol knows (m, cm, mm, um, nm)");
  }
  length.present = true;
  length.mm = value[0] * scale;
  length.field = name + (unit.empty() ? assumed : " (" + unit + ")");
  return length;
}

// A per-frame dataset of `frames` values.
std::vector<double> per_frame(hid_t file, const std::string& path, const std::string& name, hsize_t frames) {
  const Dataset d = hdf5::open_dataset(file, path, name);
  const std::vector<double> values = hdf5::read_all(d, path + ": dataset " + name, kMostFrames);
  if (values.size() != frames)
    throw Error(ErrorClass::InvalidArgument, path + ": dataset " + name + " has " + std::to_string(values.size()) +
                                                 " values for the " + std::to_string(frames) + " frames of the data");
  return values;
}

class NxtomoReader final : public ProjectionReader {
 public:
  NxtomoReader(const std::string& path, std::string data_name, Handle file, Dataset data,
               std::vector<hsize_t> projection_frames)
      : ProjectionReader(path, static_cast<int>(data.shape[2]), static_cast<int>(data.shape[1]),
                         projection_frames.size()),
        data_name_(std::move(data_name)),
        file_(std::move(file)),
        data_(std::move(data)),
        frames_(std::move(projection_frames)) {}

  void enable_intensities(std::vector<double> flat, std::vector<double> dark, double minimum_signal) {
    IntensityOptions options;
    options.minimum_signal = minimum_signal;
    set_fields(std::move(flat), std::move(dark), options);
  }

 protected:
  void read_samples(std::size_t view, int row_begin, int row_end, double* out) override {
    hdf5::QuietErrors quiet;
    hdf5::read_box(data_, {frames_[view], static_cast<hsize_t>(row_begin), 0},
                   {1, static_cast<hsize_t>(row_end - row_begin), static_cast<hsize_t>(columns_)}, out,
                   path_ + ": dataset " + data_name_ + " frame " + std::to_string(frames_[view]) + " (view " +
                       std::to_string(view) + ") rows " + std::to_string(row_begin) + ".." + std::to_string(row_end));
  }

 private:
  std::string data_name_;
  Handle file_;
  Dataset data_;
  std::vector<hsize_t> frames_;  // the data's frame of each view
};

Hdf5Scan open_nxtomo(const std::string& path, Handle file, const std::string& entry, const DxchangeOptions& options) {
  const std::string data_name = entry + "/instrument/detector/data";
  const std::string key_name = entry + "/instrument/detector/image_key";
  const std::string angle_name = entry + "/sample/rotation_angle";
  for (const std::string& name : {data_name, key_name, angle_name})
    if (!exists(file.get(), name))
      throw Error(ErrorClass::InvalidArgument, path + ": NXtomo entry " + entry + " has no dataset " + name);
  Dataset data = hdf5::open_dataset(file.get(), path, data_name);
  if (data.shape.size() != 3 || data.shape[0] == 0 || data.shape[1] == 0 || data.shape[2] == 0 ||
      data.shape[1] > std::numeric_limits<int>::max() || data.shape[2] > std::numeric_limits<int>::max())
    throw Error(ErrorClass::InvalidArgument, path + ": dataset " + data_name + " has shape " +
                                                 hdf5::shape_text(data.shape) +
                                                 "; expected (frames, rows, columns), none empty");
  const hsize_t frames = data.shape[0], rows = data.shape[1], columns = data.shape[2];
  const std::vector<double> keys = per_frame(file.get(), path, key_name, frames);
  const std::vector<double> angles = per_frame(file.get(), path, angle_name, frames);
  Hdf5Scan scan;
  scan.layout = "NXtomo";
  scan.entry = entry;
  // Angles in degrees unless the units attribute says radians.
  double to_degrees = 1.0;
  {
    const Dataset d = hdf5::open_dataset(file.get(), path, angle_name);
    const std::string unit = string_attribute(d.id.get(), "units");
    if (unit == "rad" || unit == "radian" || unit == "radians")
      to_degrees = 180.0 / M_PI;
    else if (!unit.empty() && unit != "degree" && unit != "degrees" && unit != "deg")
      throw Error(ErrorClass::InvalidArgument,
                  path + ": dataset " + angle_name + " has units '" + unit + "', not degree or rad");
    scan.angles_field = angle_name + (unit.empty() ? " (no units attribute: degrees)" : " (" + unit + ")");
  }
  std::vector<hsize_t> projection_frames;
  FieldAverage flat(static_cast<std::size_t>(rows * columns)), dark(static_cast<std::size_t>(rows * columns));
  std::vector<double> image(static_cast<std::size_t>(rows * columns));
  for (hsize_t f = 0; f < frames; ++f) {
    const double key = keys[f];
    if (key == 0) {
      if (!std::isfinite(angles[f]))
        throw Error(ErrorClass::InvalidArgument,
                    path + ": dataset " + angle_name + " value " + std::to_string(f) + " is not a number");
      projection_frames.push_back(f);
      scan.angles_deg.push_back(angles[f] * to_degrees);
    } else if (key == 1 || key == 2) {
      hdf5::read_box(data, {f, 0, 0}, {1, rows, columns}, image.data(),
                     path + ": dataset " + data_name + " frame " + std::to_string(f));
      (key == 1 ? flat : dark).add(image.data());
    } else if (key == 3) {
      ++scan.skipped_images;
    } else {
      throw Error(ErrorClass::InvalidArgument, path + ": dataset " + key_name + " value " + std::to_string(f) + " is " +
                                                   std::to_string(key) +
                                                   "; image keys are 0 (projection), 1 (flat), 2 (dark), 3 (invalid)");
    }
  }
  if (projection_frames.empty())
    throw Error(ErrorClass::InvalidArgument, path + ": dataset " + key_name + " marks no frame as a projection (0)");
  scan.flat_images = flat.count();
  scan.dark_images = dark.count();
  if (flat.count() == 0 && !options.assume_line_integrals)
    throw Error(ErrorClass::InvalidArgument,
                path + ": dataset " + key_name +
                    " marks no flat field (1): the data cannot be turned into line integrals (if they are line "
                    "integrals already, say so)");
  const std::string detector = entry + "/instrument/detector/";
  scan.pitch_u = length_field(file.get(), path, detector + "x_pixel_size");
  scan.pitch_v = length_field(file.get(), path, detector + "y_pixel_size");
  scan.sample_detector = length_field(file.get(), path, detector + "distance");
  scan.source_sample = length_field(file.get(), path, entry + "/instrument/source/distance");
  // NeXus counts a source's distance negative upstream of the sample;
  // nxtomo writes it positive. Either is the same distance.
  scan.source_sample.mm = std::abs(scan.source_sample.mm);
  scan.sample_detector.mm = std::abs(scan.sample_detector.mm);

  auto reader =
      std::make_unique<NxtomoReader>(path, data_name, std::move(file), std::move(data), std::move(projection_frames));
  if (flat.count() > 0) reader->enable_intensities(flat.mean(), dark.mean(), options.minimum_signal);
  scan.projections = std::move(reader);
  return scan;
}

}  // namespace

Hdf5Scan open_hdf5_projections_in_process(const std::string& path, const DxchangeOptions& options) {
  hdf5::QuietErrors quiet;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(ErrorClass::Io, path + ": cannot open: no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(ErrorClass::Malformed, path + ": not an HDF5 file");
  std::vector<std::string> entries;
  if (options.dataset.empty()) {
    Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) throw Error(ErrorClass::Io, path + ": cannot open the HDF5 file" + hdf5::reason());
    entries = nxtomo_entries(file.get());
    if (entries.size() == 1) return open_nxtomo(path, std::move(file), entries[0], options);
  }
  if (entries.size() > 1) {
    std::string names;
    for (const std::string& e : entries) names += (names.empty() ? "" : ", ") + e;
    throw Error(ErrorClass::InvalidArgument,
                path + ": holds " + std::to_string(entries.size()) + " NXtomo entries (" + names +
                    "); ivol reconstructs a file of one (copy one out with h5copy or nxtomo)");
  }
  if (options.dataset.empty()) {
    Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (file.valid() && !exists(file.get(), "/exchange/data"))
      throw Error(ErrorClass::InvalidArgument, path +
                                                   ": neither an NXtomo file (no top-level NXentry whose definition "
                                                   "is NXtomo) nor a DXchange file (no dataset /exchange/data; --dataset names another)");
  }
  DxchangeProjections dxchange = open_dxchange_projections_in_process(path, options);
  Hdf5Scan scan;
  scan.layout = "DXchange";
  scan.projections = std::move(dxchange.projections);
  scan.angles_deg = std::move(dxchange.theta_deg);
  if (!scan.angles_deg.empty()) scan.angles_field = "/exchange/theta";
  return scan;
}

}  // namespace ivol::convert
