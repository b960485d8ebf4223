// Projection files as scanners and tomography pipelines write them, read as
// ivol::recon::ProjectionSource (line integrals, a band of detector rows at a
// time), and the writers the phantom tool uses.
//
// Layout everywhere: views, then rows (detector v, top to bottom as stored),
// then columns (detector u) fastest. Intensities become line integrals as
//   p = −log((I − D) / (F − D))
// with D the dark field and F the flat (bright) field, each the per-pixel
// mean of all the images given, computed in double. A difference below
// IntensityOptions::minimum_signal (zero, negative, NaN or merely tiny) is
// raised to it and the pixel counted in clamped_pixels(): a pixel read twice
// counts twice. Without a dark field D = 0; without a flat field F is
// IntensityOptions::incident_intensity, which must then be given.
//
// Errors are ivol::Error (a std::runtime_error) naming the file, the view and
// rows or the dataset, and what is wrong; a file whose size or shape does not
// match is refused when it is opened, not at the first read.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/recon/projections.hpp"

namespace ivol::convert {

// What the stored samples are.
enum class StoredQuantity { LineIntegrals, Intensities };

struct IntensityOptions {
  // Files of flat (bright) and dark fields, each holding one or more images;
  // all images of all files of a kind are averaged. Same format and image
  // size as the projections (raw: same sample type and header size).
  std::vector<std::string> flat_paths;
  std::vector<std::string> dark_paths;
  double incident_intensity = 0.0;  // F where no flat field is given; must be > 0 then
  double minimum_signal = 1e-3;     // floor of I − D and F − D
};

// A projection file being read. Not thread-safe (the interface reads from
// one thread at a time).
// The largest detector the readers accept, in pixels.
constexpr std::uint64_t kMaxDetectorPixels = std::uint64_t{1} << 27;

class ProjectionReader : public ivol::recon::ProjectionSource {
 public:
  ~ProjectionReader() override;
  int columns() const override { return columns_; }
  int rows() const override { return rows_; }
  std::size_t view_count() const override { return views_; }
  // Reads only the stored rows [row_begin, row_end) of `view` (as far as the
  // format allows: whole strips or tiles of a TIFF, whole chunks of HDF5).
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) final;

  const std::string& path() const { return path_; }
  virtual StoredQuantity quantity() const {
    return intensities_ ? StoredQuantity::Intensities : StoredQuantity::LineIntegrals;
  }
  // Pixels whose I − D or F − D was raised to the floor, over all reads so far.
  std::uint64_t clamped_pixels() const { return clamped_; }

 protected:
  ProjectionReader(std::string path, int columns, int rows, std::size_t views);
  // The stored values of rows [row_begin, row_end) of `view`, converted to
  // double (exactly, for 16- and 32-bit samples). Arguments are checked.
  virtual void read_samples(std::size_t view, int row_begin, int row_end, double* out) = 0;
  // Turns the reader into an intensity reader. `flat` and `dark` are per-pixel
  // means (rows × columns) or empty (see the conventions above).
  void set_fields(std::vector<double> flat, std::vector<double> dark, const IntensityOptions& options);
  // For a reader whose conversion to line integrals happens elsewhere (in
  // the process that reads HDF5): the pixels it clamped.
  void count_clamped(std::uint64_t pixels) { clamped_ += pixels; }

  std::string path_;
  int columns_;
  int rows_;
  std::size_t views_;

 private:
  bool intensities_ = false;
  std::vector<double> dark_;         // D per pixel (empty: 0)
  std::vector<double> denominator_;  // F − D per pixel, floored
  std::vector<std::uint8_t> bad_denominator_;
  double floor_ = 1e-3;
  std::vector<double> scratch_;
  std::uint64_t clamped_ = 0;
};

// Sums images of `pixels` doubles into a per-pixel mean, for the readers'
// flat and dark fields.
class FieldAverage {
 public:
  explicit FieldAverage(std::size_t pixels) : sum_(pixels, 0.0) {}
  void add(const double* image);
  std::size_t count() const { return count_; }
  std::vector<double> mean() const;  // empty when no image was added

 private:
  std::vector<double> sum_;
  std::size_t count_ = 0;
};

// --- Raw: bare little-endian samples after an optional header ---------------

enum class RawSampleType { UInt16, Float32 };

struct RawProjectionLayout {
  int columns = 0;
  int rows = 0;
  std::size_t views = 0;
  RawSampleType sample = RawSampleType::Float32;
  StoredQuantity quantity = StoredQuantity::LineIntegrals;  // UInt16 samples are always intensities
  std::uint64_t header_bytes = 0;                           // skipped at the start of every file
};

// The file must hold exactly header_bytes + views·rows·columns samples; flat
// and dark files header_bytes + k·rows·columns samples, k ≥ 1. Reads use
// pread of the requested rows only.
std::unique_ptr<ProjectionReader> open_raw_projections(const std::string& path, const RawProjectionLayout& layout,
                                                       const IntensityOptions& intensity = {});

// Writes float32 little-endian line integrals, no header (a temporary file
// renamed into place when complete).
void write_raw_projections(const std::string& path, ivol::recon::ProjectionSource& source);

// --- TIFF: one page per view ---------------------------------------------

// `source` is one TIFF file (every page a view, so a multi-page file is a
// whole scan), a folder (its .tif/.tiff files, one or more pages each, in
// natural order: p2 before p10, which for zero-padded names is plain
// lexicographic order) or a glob pattern such as "scan/proj_*.tif" (its
// matches in the same order). 16-bit unsigned or 32-bit float samples, one
// per pixel, any compression libtiff decodes, striped or tiled; all pages the
// same size and type. Flat and dark paths are resolved the same way. uint16
// samples are always intensities.
std::unique_ptr<ProjectionReader> open_tiff_projections(const std::string& source, StoredQuantity quantity,
                                                        const IntensityOptions& intensity = {});
// The same with the files given in order.
std::unique_ptr<ProjectionReader> open_tiff_projections(const std::vector<std::string>& files, StoredQuantity quantity,
                                                        const IntensityOptions& intensity = {});
// The files `source` resolves to, in the order above.
std::vector<std::string> resolve_tiff_files(const std::string& source);

// --- ITK images: MetaImage (.mha, .mhd) and NRRD (.nrrd, .nhdr) -----------

// A 3-D stack (columns, rows, views) of any scalar type, raw or compressed
// (inflated once into a temporary file, since reconstruction reads bands of
// rows of every view). Integer samples are always intensities. Flat and
// dark fields are ITK images too (one image or a stack each).
struct ItkImageScan {
  std::unique_ptr<ProjectionReader> projections;
  // The header's spacing (detector pitch) and origin (RTK's projection
  // origin: the first pixel's position on the detector), where it has them,
  // and the field each came from.
  bool has_pitch = false;
  std::array<double, 2> pitch{1.0, 1.0};
  std::string pitch_field;
  bool has_origin = false;
  std::array<double, 2> origin{0.0, 0.0};
  std::string origin_field;
  std::string unit;  // NRRD space units; empty for MetaImage (millimetres by ITK's convention)
};
ItkImageScan open_itk_image_projections(const std::string& path, StoredQuantity quantity,
                                        const IntensityOptions& intensity = {});

// --- HDF5 DXchange --------------------------------------------------------

struct DxchangeOptions {
  // Without /exchange/data_white the data are refused, unless this says they
  // are line integrals already.
  bool assume_line_integrals = false;
  double minimum_signal = 1e-3;
  // The projections' dataset (views, rows, columns); empty: /exchange/data.
  // Named, the file is read as DXchange whatever else it holds (an NXtomo
  // entry's data, an ITK image stack's /ITKImage/0/VoxelData, ...); flat and
  // dark fields still come from /exchange/data_white and data_dark.
  std::string dataset;
  // What the child process that runs libhdf5 may allocate (recon's
  // --memory); 0: kDefaultChildMemory (isolated_worker.hpp).
  std::uint64_t memory_bytes = 0;
};

struct DxchangeProjections {
  std::unique_ptr<ProjectionReader> projections;
  std::vector<double> theta_deg;  // /exchange/theta (degrees), one per view; empty if the file has none
};

// /exchange/data (views, rows, columns) of any integer or float type, read by
// hyperslab; /exchange/data_white and /exchange/data_dark (n, rows, columns)
// or (rows, columns), averaged over n; with data_white the data are
// intensities (data_dark optional), without it see assume_line_integrals.
// libhdf5 runs in a child process of its own (isolated_worker.hpp): a crash
// of the library on a damaged file is an ivol::Error(Malformed) naming it.
DxchangeProjections open_dxchange_projections(const std::string& path, const DxchangeOptions& options = {});
// The same in this process, as the child runs it; for the fuzz harness,
// which must see the library's crashes to tell them from ivol's.
DxchangeProjections open_dxchange_projections_in_process(const std::string& path, const DxchangeOptions& options = {});

// --- HDF5 projections of either layout: NeXus NXtomo or DXchange ----------

// A length the file gives, converted to mm, and the field it came from.
struct LengthField {
  bool present = false;
  double mm = 0.0;
  std::string field;  // dataset path and units, for "which value came from where"
};

struct Hdf5Scan {
  std::unique_ptr<ProjectionReader> projections;
  std::string layout;              // "NXtomo" or "DXchange"
  std::string entry;               // the NXtomo entry ("/entry0000"); empty for DXchange
  std::vector<double> angles_deg;  // one per view; empty if the file has none
  std::string angles_field;        // where they came from
  LengthField pitch_u, pitch_v;    // NXtomo detector x_pixel_size, y_pixel_size
  LengthField source_sample;       // NXtomo instrument/source/distance (absolute value)
  LengthField sample_detector;     // NXtomo instrument/detector/distance
  std::uint64_t flat_images = 0, dark_images = 0, skipped_images = 0;  // NXtomo image keys 1, 2, 3
};

// A file with one NXtomo entry (a top-level NXentry whose definition is
// NXtomo) is read as NXtomo: ENTRY/instrument/detector/data (frames, rows,
// columns) with image_key per frame, 0 projection, 1 flat, 2 dark, 3
// invalid (skipped); flats and darks averaged over all their frames, as
// DXchange's readers do; angles from ENTRY/sample/rotation_angle (degrees,
// or radians by its units attribute); lengths by their units attributes
// (metres without one). Without flat frames the data must be line
// integrals already (options.assume_line_integrals). A file of several
// NXtomo entries is refused; one without any is read as DXchange.
// libhdf5 runs in a child process (as for open_dxchange_projections).
Hdf5Scan open_hdf5_projections(const std::string& path, const DxchangeOptions& options = {});
Hdf5Scan open_hdf5_projections_in_process(const std::string& path, const DxchangeOptions& options = {});

// Flat and dark images (rows × columns each) for write_dxchange.
struct FieldImages {
  std::vector<float> flat;  // empty: write line integrals, no data_white
  std::vector<float> dark;  // empty: no data_dark (only with a flat)
};

// Writes /exchange/data as float32: the line integrals, or with a flat field
// the intensities D + (F − D)·exp(−p) they come from, plus data_white and
// data_dark of shape (1, rows, columns); /exchange/theta float64 degrees.
// Through a temporary file renamed into place.
void write_dxchange(const std::string& path, ivol::recon::ProjectionSource& source,
                    const std::vector<double>& angles_deg, const FieldImages& fields = {});

}  // namespace ivol::convert
