// Projection readers against files written by other implementations (numpy's
// tofile, tifffile, h5py) with known intensities, flats and darks: the line
// integrals must be −log((I − D)/(F − D)), computed here in double from the
// same integer formulas the Python script evaluates; row bands must equal the
// matching part of whole-image reads; and our writers are read back by numpy
// and h5py.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "ivol/error.hpp"
#include "ivol/recon/projections.hpp"
#include "projection_io.hpp"
#include "test_support.hpp"

namespace ivol::convert {
namespace {

constexpr int kViews = 5, kRows = 12, kColumns = 17;

// --- The scan, as both sides compute it -----------------------------------

double intensity(int v, int r, int c) {
  if ((r * 17 + c + 3 * v) % 23 == 0) return 50.0;  // below the dark field: clamped
  return (1000 + 37 * c + 101 * r + 211 * v) % 3000 + 20;
}
double flat(int k, int r, int c) { return (r == 3 && c == 4) ? 90.0 : 3200.0 + 13 * c + 7 * r + 50 * k; }
double dark(int k, int r, int c) { return 100.0 + (c + 3 * r + 5 * k) % 40; }
float line_integral(int v, int r, int c) { return static_cast<float>((c * 0.25 + r * 0.5 - v) / 7.0); }

const char* kPythonScan = R"(
import sys, os
import numpy as np
V, R, C = 5, 12, 17
v, r, c = np.meshgrid(np.arange(V), np.arange(R), np.arange(C), indexing='ij')
I = ((1000 + 37 * c + 101 * r + 211 * v) % 3000 + 20).astype(np.uint16)
I[(r * 17 + c + 3 * v) % 23 == 0] = 50
rr, cc = np.meshgrid(np.arange(R), np.arange(C), indexing='ij')
F = np.stack([3200 + 13 * cc + 7 * rr + 50 * k for k in range(3)]).astype(np.uint16)
F[:, 3, 4] = 90
D = np.stack([100 + (cc + 3 * rr + 5 * k) % 40 for k in range(2)]).astype(np.uint16)
P = ((c * 0.25 + r * 0.5 - v) / 7.0).astype(np.float32)
)";

// The reference: flats and darks averaged, differences floored, in double.
struct Expected {
  std::vector<double> values;  // views × rows × columns
  std::uint64_t clamped = 0;   // per whole pass
};

Expected expected_line_integrals(double scale, int flats, int darks, double floor = 1e-3) {
  Expected e;
  for (int v = 0; v < kViews; ++v)
    for (int r = 0; r < kRows; ++r)
      for (int c = 0; c < kColumns; ++c) {
        double f = 0.0, d = 0.0;
        for (int k = 0; k < flats; ++k) f += flat(k, r, c) / scale;
        for (int k = 0; k < darks; ++k) d += dark(k, r, c) / scale;
        f /= flats;
        d = darks ? d / darks : 0.0;
        double numerator = intensity(v, r, c) / scale - d;
        double denominator = f - d;
        const bool clamped = numerator < floor || denominator < floor;
        numerator = std::max(numerator, floor);
        denominator = std::max(denominator, floor);
        e.values.push_back(-std::log(numerator / denominator));
        e.clamped += clamped ? 1 : 0;
      }
  return e;
}

Expected expected_stored_line_integrals() {
  Expected e;
  for (int v = 0; v < kViews; ++v)
    for (int r = 0; r < kRows; ++r)
      for (int c = 0; c < kColumns; ++c) e.values.push_back(line_integral(v, r, c));
  return e;
}

std::string dir() { return ivol::test::temp_dir() + "/proj"; }
std::string at(const std::string& name) { return dir() + "/" + name; }

// Runs a Python script given as text after kPythonScan; argv[1] is the folder.
void run_python(const std::string& script) {
  const std::string path = ivol::test::temp_path("projection_script.py");
  std::ofstream(path) << kPythonScan << script;
  const auto result = ivol::test::run_command(std::string(IVOL_PYTHON) + " " + path + " " + dir());
  ASSERT_EQ(result.exit_code, 0) << result.output;
}

class ProjectionFiles : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::filesystem::create_directories(dir() + "/views");
    run_python(R"(
import tifffile, h5py
d = sys.argv[1]
def raw(name, array, header=b''):
    with open(os.path.join(d, name), 'wb') as f:
        f.write(header)
        f.write(array.astype(array.dtype.newbyteorder('<')).tobytes())
hdr = b'H' * 32
raw('u16.raw', I, hdr)
raw('flats.raw', F, hdr)
raw('dark0.raw', D[0], hdr)
raw('dark1.raw', D[1], hdr)
raw('li.raw', P)
raw('short.raw', P)
with open(os.path.join(d, 'short.raw'), 'r+b') as f:
    f.truncate(V * R * C * 4 - 1)

# uint16, one multi-page file, several strips per page, uncompressed
tifffile.imwrite(os.path.join(d, 'multi.tif'), I, rowsperstrip=5, photometric='minisblack')
tifffile.imwrite(os.path.join(d, 'flats.tif'), F, photometric='minisblack')
tifffile.imwrite(os.path.join(d, 'dark0.tif'), D[0], photometric='minisblack')
tifffile.imwrite(os.path.join(d, 'dark1.tif'), D[1], photometric='minisblack')
# float32 intensities, one deflate-compressed file per view;
# names that sort wrongly as plain strings
for i in range(V):
    tifffile.imwrite(os.path.join(d, 'views', 'p%d.tif' % (8 + i)), (I[i] / 4096.0).astype(np.float32),
                     compression='zlib', rowsperstrip=4, photometric='minisblack')
tifffile.imwrite(os.path.join(d, 'flats_f32.tif'), (F / 4096.0).astype(np.float32), photometric='minisblack')
tifffile.imwrite(os.path.join(d, 'darks_f32.tif'), (D / 4096.0).astype(np.float32), photometric='minisblack')
# float32 line integrals, tiled
tifffile.imwrite(os.path.join(d, 'tiled.tif'), P, tile=(16, 16), photometric='minisblack')
# uint16, deflate, 4 rows per strip; strip 1 of page 1 (rows 4..7 of view 1) destroyed
path = os.path.join(d, 'damaged.tif')
tifffile.imwrite(path, I, compression='zlib', rowsperstrip=4, photometric='minisblack')
with tifffile.TiffFile(path) as t:
    offset, size = t.pages[1].dataoffsets[1], t.pages[1].databytecounts[1]
with open(path, 'r+b') as f:
    f.seek(offset)
    f.write(b'\xff' * size)

theta = np.linspace(0.0, 180.0, V, endpoint=False).astype(np.float32)
with h5py.File(os.path.join(d, 'dx_u16.h5'), 'w') as f:
    f.create_dataset('/exchange/data', data=I, chunks=(1, 4, C), compression='gzip')
    f.create_dataset('/exchange/data_white', data=F)
    f.create_dataset('/exchange/data_dark', data=D)
    f.create_dataset('/exchange/theta', data=theta)
with h5py.File(os.path.join(d, 'dx_i32.h5'), 'w') as f:
    f.create_dataset('/exchange/data', data=I.astype(np.int32))
    f.create_dataset('/exchange/data_white', data=F[0].astype(np.float64))  # one 2-D flat, no dark
with h5py.File(os.path.join(d, 'dx_li.h5'), 'w') as f:
    f.create_dataset('/exchange/data', data=P.astype(np.float64))
    f.create_dataset('/exchange/theta', data=np.arange(V + 1.0))
)");
  }

  static std::vector<float> read_all(ivol::recon::ProjectionSource& source) {
    std::vector<float> all(static_cast<std::size_t>(kViews) * kRows * kColumns);
    for (int v = 0; v < kViews; ++v)
      source.read_rows(v, 0, kRows, all.data() + static_cast<std::size_t>(v) * kRows * kColumns);
    return all;
  }

  // Whole images match the reference, the clamped count is the reference's,
  // and bands of rows equal the matching part of the whole images.
  static void check(ProjectionReader& reader, const Expected& expected) {
    ASSERT_EQ(reader.columns(), kColumns);
    ASSERT_EQ(reader.rows(), kRows);
    ASSERT_EQ(reader.view_count(), std::size_t{kViews});
    const std::vector<float> all = read_all(reader);
    int mismatches = 0;
    for (std::size_t i = 0; i < all.size(); ++i)
      if (!(std::abs(all[i] - expected.values[i]) <= 1e-6 * std::max(1.0, std::abs(expected.values[i]))) &&
          mismatches++ < 5)
        ADD_FAILURE() << reader.path() << " sample " << i << ": " << all[i] << " != " << expected.values[i];
    EXPECT_EQ(mismatches, 0);
    EXPECT_EQ(reader.clamped_pixels(), expected.clamped);
    const std::pair<int, int> bands[] = {{0, 1}, {3, 8}, {4, 12}, {11, 12}, {5, 5}};
    for (int v : {0, 2, kViews - 1})
      for (const auto& [r0, r1] : bands) {
        std::vector<float> band(static_cast<std::size_t>(r1 - r0) * kColumns);
        reader.read_rows(v, r0, r1, band.data());
        const float* whole = all.data() + (static_cast<std::size_t>(v) * kRows + r0) * kColumns;
        for (std::size_t i = 0; i < band.size(); ++i)
          ASSERT_EQ(band[i], whole[i]) << reader.path() << " view " << v << " rows " << r0 << ".." << r1;
      }
  }
};

template <typename Function>
std::string error_of(Function f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "(no error)";
}

// The reference's clamping must be exercised, or the count checks nothing.
TEST_F(ProjectionFiles, ReferenceClampsSomePixels) {
  const Expected e = expected_line_integrals(1.0, 3, 2);
  EXPECT_GT(e.clamped, std::uint64_t{kViews});  // the dead flat pixel in every view, and more
  EXPECT_LT(e.clamped, std::uint64_t{kViews * kRows * kColumns / 4});
}

TEST_F(ProjectionFiles, RawUInt16WithHeaderFlatsAndDarks) {
  RawProjectionLayout layout{kColumns, kRows, kViews, RawSampleType::UInt16, StoredQuantity::Intensities, 32};
  IntensityOptions fields;
  fields.flat_paths = {at("flats.raw")};
  fields.dark_paths = {at("dark0.raw"), at("dark1.raw")};
  auto reader = open_raw_projections(at("u16.raw"), layout, fields);
  EXPECT_EQ(reader->quantity(), StoredQuantity::Intensities);
  check(*reader, expected_line_integrals(1.0, 3, 2));
}

TEST_F(ProjectionFiles, RawFloatLineIntegrals) {
  RawProjectionLayout layout{kColumns, kRows, kViews, RawSampleType::Float32, StoredQuantity::LineIntegrals, 0};
  auto reader = open_raw_projections(at("li.raw"), layout);
  check(*reader, expected_stored_line_integrals());
}

TEST_F(ProjectionFiles, RawSizeMismatchRefusedAtOpen) {
  RawProjectionLayout layout{kColumns, kRows, kViews, RawSampleType::Float32, StoredQuantity::LineIntegrals, 0};
  const std::string message = error_of([&] { open_raw_projections(at("short.raw"), layout); });
  EXPECT_NE(message.find(at("short.raw")), std::string::npos) << message;
  EXPECT_NE(message.find(std::to_string(kViews * kRows * kColumns * 4 - 1) + " bytes"), std::string::npos) << message;
  EXPECT_NE(message.find("need " + std::to_string(kViews * kRows * kColumns * 4)), std::string::npos) << message;
  // A flat file that is not a whole number of images.
  RawProjectionLayout u16{kColumns, kRows, kViews, RawSampleType::UInt16, StoredQuantity::Intensities, 32};
  IntensityOptions fields;
  fields.flat_paths = {at("li.raw")};
  const std::string flat_message = error_of([&] { open_raw_projections(at("u16.raw"), u16, fields); });
  EXPECT_NE(flat_message.find(at("li.raw")), std::string::npos) << flat_message;
  EXPECT_NE(flat_message.find("flat"), std::string::npos) << flat_message;
  // Intensities with neither a flat field nor an incident intensity.
  EXPECT_NE(error_of([&] { open_raw_projections(at("u16.raw"), u16); }).find("flat field"), std::string::npos);
}

TEST_F(ProjectionFiles, OutOfRangeReadNamesTheView) {
  RawProjectionLayout layout{kColumns, kRows, kViews, RawSampleType::Float32, StoredQuantity::LineIntegrals, 0};
  auto reader = open_raw_projections(at("li.raw"), layout);
  std::vector<float> out(kRows * kColumns);
  const std::string message = error_of([&] { reader->read_rows(kViews, 0, 1, out.data()); });
  EXPECT_NE(message.find("view " + std::to_string(kViews)), std::string::npos) << message;
  EXPECT_NE(error_of([&] { reader->read_rows(0, 3, kRows + 1, out.data()); }).find("outside"), std::string::npos);
}

TEST_F(ProjectionFiles, TiffMultiPageUInt16) {
  IntensityOptions fields;
  fields.flat_paths = {at("flats.tif")};
  fields.dark_paths = {at("dark?.tif")};  // a glob: both single-page darks
  auto reader = open_tiff_projections(at("multi.tif"), StoredQuantity::Intensities, fields);
  check(*reader, expected_line_integrals(1.0, 3, 2));
}

TEST_F(ProjectionFiles, TiffFolderOfCompressedFloatFilesInNaturalOrder) {
  EXPECT_EQ(resolve_tiff_files(dir() + "/views").front(), dir() + "/views/p8.tif");
  EXPECT_EQ(resolve_tiff_files(dir() + "/views/p*.tif").back(), dir() + "/views/p12.tif");
  IntensityOptions fields;
  fields.flat_paths = {at("flats_f32.tif")};
  fields.dark_paths = {at("darks_f32.tif")};
  auto reader = open_tiff_projections(dir() + "/views", StoredQuantity::Intensities, fields);
  check(*reader, expected_line_integrals(4096.0, 3, 2));
}

TEST_F(ProjectionFiles, TiffTiledLineIntegrals) {
  auto reader = open_tiff_projections(at("tiled.tif"), StoredQuantity::LineIntegrals);
  check(*reader, expected_stored_line_integrals());
}

TEST_F(ProjectionFiles, TiffBandReadsDecodeOnlyTheirStrips) {
  IntensityOptions fields;
  fields.incident_intensity = 4000.0;
  auto reader = open_tiff_projections(at("damaged.tif"), StoredQuantity::Intensities, fields);
  // Bands that avoid the destroyed strip 1 of view 1 read, with the right values.
  std::vector<float> band(4 * kColumns);
  for (int r0 : {0, 8}) {
    reader->read_rows(1, r0, r0 + 4, band.data());
    for (int r = r0; r < r0 + 4; ++r)
      for (int c = 0; c < kColumns; ++c)
        ASSERT_NEAR(band[(r - r0) * kColumns + c], -std::log(intensity(1, r, c) / 4000.0), 1e-6) << r << "," << c;
  }
  const std::string message = error_of([&] { reader->read_rows(1, 2, 6, band.data()); });
  EXPECT_NE(message.find(at("damaged.tif")), std::string::npos) << message;
  EXPECT_NE(message.find("view 1"), std::string::npos) << message;
  EXPECT_NE(message.find("strip 1"), std::string::npos) << message;
}

TEST_F(ProjectionFiles, DxchangeUInt16WithWhiteDarkAndTheta) {
  DxchangeProjections scan = open_dxchange_projections(at("dx_u16.h5"));
  ASSERT_EQ(scan.theta_deg.size(), std::size_t{kViews});
  for (int i = 0; i < kViews; ++i) EXPECT_EQ(scan.theta_deg[i], 36.0 * i);
  check(*scan.projections, expected_line_integrals(1.0, 3, 2));
}

// Bytes this process has read so far (/proc/self/io rchar).
std::uint64_t bytes_read_so_far() {
  std::ifstream io("/proc/self/io");
  std::string key;
  std::uint64_t value = 0;
  while (io >> key >> value)
    if (key == "rchar:") return value;
  return 0;
}

// Chunks of 32 views: read view by view, each chunk must be read (and
// inflated) once, not once per view, which HDF5's default 1 MiB chunk cache
// would do for these 2 MiB chunks.
TEST_F(ProjectionFiles, DxchangeChunksSpanningViewsAreReadOnce) {
  run_python(R"(
import h5py
d = sys.argv[1]
with h5py.File(os.path.join(d, 'dx_chunked.h5'), 'w') as f:
    data = np.random.default_rng(7).random((64, 128, 128), dtype=np.float32)
    f.create_dataset('/exchange/data', data=data, chunks=(32, 128, 128), compression='gzip', compression_opts=1)
)");
  const std::string path = at("dx_chunked.h5");
  const std::uint64_t file_bytes = std::filesystem::file_size(path);
  const std::uint64_t before = bytes_read_so_far();
  DxchangeProjections scan = open_dxchange_projections_in_process(path, {true, 1e-3});
  std::vector<float> image(128 * 128);
  for (std::size_t v = 0; v < 64; ++v) scan.projections->read_rows(v, 0, 128, image.data());
  const std::uint64_t read = bytes_read_so_far() - before;
  // Once: about the file's size; once per view: 32 times that.
  EXPECT_LT(read, 2 * file_bytes) << read << " bytes read for a file of " << file_bytes;
}

TEST_F(ProjectionFiles, DxchangeInt32WithOneFlatImage) {
  DxchangeProjections scan = open_dxchange_projections(at("dx_i32.h5"));
  EXPECT_TRUE(scan.theta_deg.empty());
  check(*scan.projections, expected_line_integrals(1.0, 1, 0));
}

TEST_F(ProjectionFiles, DxchangeWithoutWhite) {
  const std::string message = error_of([] { open_dxchange_projections(at("dx_li.h5")); });
  EXPECT_NE(message.find("/exchange/data_white"), std::string::npos) << message;
  EXPECT_NE(message.find(at("dx_li.h5")), std::string::npos) << message;
  DxchangeOptions options;
  options.assume_line_integrals = true;
  // theta has one angle too many
  const std::string theta_message = error_of([&] { open_dxchange_projections(at("dx_li.h5"), options); });
  EXPECT_NE(theta_message.find("/exchange/theta"), std::string::npos) << theta_message;
}

TEST_F(ProjectionFiles, WritersReadBackByNumpyAndH5py) {
  std::vector<float> values;
  for (int v = 0; v < kViews; ++v)
    for (int r = 0; r < kRows; ++r)
      for (int c = 0; c < kColumns; ++c) values.push_back(line_integral(v, r, c));
  ivol::recon::InMemoryProjections source(kColumns, kRows, kViews, values);
  write_raw_projections(at("written.raw"), source);
  FieldImages fields;
  for (int r = 0; r < kRows; ++r)
    for (int c = 0; c < kColumns; ++c) {
      fields.flat.push_back(static_cast<float>(flat(1, r, c) + (r == 3 && c == 4 ? 4000.0 : 0.0)));
      fields.dark.push_back(static_cast<float>(dark(0, r, c)));
    }
  const std::vector<double> angles = {0.0, 72.0, 144.0, 216.0, 288.0};
  write_dxchange(at("written.h5"), source, angles, fields);
  write_dxchange(at("written_li.h5"), source, angles);
  run_python(R"(
import h5py
d = sys.argv[1]
raw = np.fromfile(os.path.join(d, 'written.raw'), dtype='<f4')
assert raw.size == V * R * C, raw.size
assert np.array_equal(raw.reshape(V, R, C), P)
with h5py.File(os.path.join(d, 'written.h5'), 'r') as f:
    data = f['/exchange/data']
    assert data.dtype == np.float32 and data.shape == (V, R, C), (data.dtype, data.shape)
    white = f['/exchange/data_white'][...]
    dark = f['/exchange/data_dark'][...]
    assert white.shape == (1, R, C) and dark.shape == (1, R, C)
    flat1 = F[1].astype(np.float64); flat1[3, 4] += 4000
    assert np.array_equal(white[0], flat1.astype(np.float32)) and np.array_equal(dark[0], D[0])
    expected = D[0] + (flat1 - D[0]) * np.exp(-P.astype(np.float64))
    assert np.allclose(data[...], expected, rtol=1e-6, atol=0), np.abs(data[...] - expected).max()
    assert np.array_equal(f['/exchange/theta'][...], [0, 72, 144, 216, 288])
with h5py.File(os.path.join(d, 'written_li.h5'), 'r') as f:
    assert 'data_white' not in f['/exchange']
    assert np.array_equal(f['/exchange/data'][...], P)
)");
  // And our own reader gets the line integrals back.
  DxchangeProjections scan = open_dxchange_projections(at("written.h5"));
  const std::vector<float> back = read_all(*scan.projections);
  for (std::size_t i = 0; i < back.size(); ++i) ASSERT_NEAR(back[i], values[i], 2e-5) << i;
  EXPECT_EQ(scan.projections->clamped_pixels(), 0u);
  DxchangeOptions options;
  options.assume_line_integrals = true;
  DxchangeProjections li = open_dxchange_projections(at("written_li.h5"), options);
  EXPECT_EQ(read_all(*li.projections), values);
}

}  // namespace
}  // namespace ivol::convert
