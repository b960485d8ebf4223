// FDK on OpenCL: the shared layouts agree, the device path matches a
// double-precision CPU reference to float round-off, slabs do not change a
// voxel's bits, and reconstructions of analytic phantoms meet RTK's
// thresholds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <numeric>

#include "ball_projections.hpp"
#include "fdk_plan.hpp"
#include "ivol/recon/displaced_detector.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/fdk_reference.hpp"
#include "ivol/recon/phantom.hpp"
#include "opencl_runtime.hpp"

namespace ivol::recon {
namespace {

using test::project_ball;

TEST(Fdk, LayoutAgrees) {
  const auto devices = detail::enumerate_devices();
  ASSERT_FALSE(devices.empty()) << "no OpenCL device (install pocl-opencl-icd)";
  for (const auto& device : devices) {
    const std::vector<int> v = detail::probe_device_layout(device);
    EXPECT_EQ(v[0], static_cast<int>(sizeof(FilterView))) << device.info.name;
    EXPECT_EQ(v[1], static_cast<int>(offsetof(FilterView, scale)));
    EXPECT_EQ(v[2], static_cast<int>(offsetof(FilterView, sdd)));
    EXPECT_EQ(v[3], static_cast<int>(offsetof(FilterView, foot_u)));
    EXPECT_EQ(v[4], static_cast<int>(offsetof(FilterView, foot_v)));
    EXPECT_EQ(v[5], static_cast<int>(offsetof(FilterView, u_first)));
    EXPECT_EQ(v[6], static_cast<int>(offsetof(FilterView, v_first)));
    EXPECT_EQ(v[7], static_cast<int>(offsetof(FilterView, pitch_u)));
    EXPECT_EQ(v[8], static_cast<int>(offsetof(FilterView, pitch_v)));
    EXPECT_EQ(v[9], static_cast<int>(offsetof(FilterView, parker_beta)));
    EXPECT_EQ(v[10], static_cast<int>(offsetof(FilterView, parker_delta)));
    EXPECT_EQ(v[11], static_cast<int>(offsetof(FilterView, parker_sign)));
    EXPECT_EQ(v[12], static_cast<int>(offsetof(FilterView, reserved)));
    EXPECT_EQ(v[13], static_cast<int>(sizeof(BackprojectView)));
    EXPECT_EQ(v[14], static_cast<int>(offsetof(BackprojectView, column)));
    EXPECT_EQ(v[15], static_cast<int>(offsetof(BackprojectView, row)));
    EXPECT_EQ(v[16], static_cast<int>(offsetof(BackprojectView, depth)));
    EXPECT_EQ(v[17], IVOL_BAND_BORDER_BEFORE);
    EXPECT_EQ(v[18], IVOL_BAND_BORDER_AFTER);
    EXPECT_EQ(v[19], IVOL_BACKPROJECT_BATCH);
    EXPECT_EQ(v[20], IVOL_BACKPROJECT_DEPTH);
    EXPECT_EQ(v[21], static_cast<int>(sizeof(FineTask)));
    EXPECT_EQ(v[22], static_cast<int>(offsetof(FineTask, run_i)));
    EXPECT_EQ(v[23], static_cast<int>(offsetof(FineTask, count)));
    EXPECT_EQ(v[24], static_cast<int>(sizeof(CoarseTask)));
    EXPECT_EQ(v[25], static_cast<int>(offsetof(CoarseTask, quarter_i)));
    EXPECT_EQ(v[26], static_cast<int>(offsetof(CoarseTask, quarter_k)));
    EXPECT_EQ(v[27], static_cast<int>(offsetof(CoarseTask, reserved)));
  }
}

struct SmallCase {
  ScanGeometry geometry;
  VolumeGrid grid;
};

SmallCase small_case(double arc, std::size_t views, double offset_u = 0, double offset_v = 0) {
  SmallCase c;
  c.geometry = circular_scan({48, 40, 1.6, 1.6}, views, 300.0, 600.0, arc, 0.3, offset_u, offset_v);
  c.grid = VolumeGrid::centred({24, 22, 20}, 1.5);
  return c;
}

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// Float round-off of the double-precision reference: within 2e-5 of its
// largest value everywhere.
void expect_matches_reference(const std::vector<float>& device, const std::vector<double>& reference) {
  const double scale = max_abs(reference);
  ASSERT_GT(scale, 0.01);
  ASSERT_EQ(device.size(), reference.size());
  double worst = 0;
  for (std::size_t i = 0; i < device.size(); ++i) worst = std::max(worst, std::abs(device[i] - reference[i]));
  EXPECT_LT(worst / scale, 2e-5) << "worst difference " << worst << " of " << scale;
}

TEST(Fdk, MatchesDoubleReference) {
  for (const bool short_scan : {false, true}) {
    SCOPED_TRACE(short_scan ? "short scan" : "full scan");
    SmallCase c = short_scan ? small_case(M_PI * 1.3, 50, 2.0, -1.5) : small_case(2 * M_PI, 60, 2.0, -1.5);
    c.geometry.views[3].source_offset_u = 1.0;  // one odd view
    InMemoryProjections p = project_ball(c.geometry, {3.0, -2.0, 1.0}, 11.0, 0.02);
    const std::vector<double> reference = reconstruct_fdk_reference(p, c.geometry, c.grid, RampWindow::Hann, 0.9);
    FdkOptions options;
    options.window = RampWindow::Hann;
    options.cutoff = 0.9;
    const std::vector<float> device = reconstruct_fdk_dense(p, c.geometry, c.grid, options);
    expect_matches_reference(device, reference);
  }
}

// Anisotropic voxels (finer in-plane than along the axis) and a non-cubic,
// off-centre grid: every voxel still sits where the reference puts it.
TEST(Fdk, AnisotropicVoxelsMatchDoubleReference) {
  SmallCase c = small_case(2 * M_PI, 60, 1.0, 0.5);
  c.grid = VolumeGrid::centred({30, 26, 14}, Vec3{0.8, 1.1, 2.0});
  c.grid.origin[0] += 2.5;  // a region of interest off the axis
  InMemoryProjections p = project_ball(c.geometry, {3.0, -2.0, 1.0}, 9.0, 0.02);
  const std::vector<double> reference = reconstruct_fdk_reference(p, c.geometry, c.grid, RampWindow::Hann, 0.9);
  FdkOptions options;
  options.window = RampWindow::Hann;
  options.cutoff = 0.9;
  const std::vector<float> device = reconstruct_fdk_dense(p, c.geometry, c.grid, options);
  expect_matches_reference(device, reference);
  // The ball's density is recovered at its centre: the axes are not swapped.
  const auto at = [&](double x, double y, double z) {
    const auto i = static_cast<std::size_t>(std::lround((x - c.grid.origin[0]) / c.grid.voxel_size[0]));
    const auto j = static_cast<std::size_t>(std::lround((y - c.grid.origin[1]) / c.grid.voxel_size[1]));
    const auto k = static_cast<std::size_t>(std::lround((z - c.grid.origin[2]) / c.grid.voxel_size[2]));
    return device[(k * c.grid.size[1] + j) * c.grid.size[0] + i];
  };
  EXPECT_NEAR(at(3.0, -2.0, 1.0), 0.02, 0.004);
  EXPECT_NEAR(at(-8.0, 8.0, 1.0), 0.0, 0.004);
}

TEST(Fdk, SlabsDoNotChangeBits) {
  SmallCase c = small_case(2 * M_PI, 40, 1.0, 3.0);
  InMemoryProjections p = project_ball(c.geometry, {0, 0, 0}, 12.0, 0.02);
  FdkReport whole_report;
  const std::vector<float> whole = reconstruct_fdk_dense(p, c.geometry, c.grid, {}, &whole_report);
  EXPECT_EQ(whole_report.slab_count, 1U);
  for (std::uint32_t slices : {1U, 3U, 7U}) {
    FdkOptions options;
    options.max_slab_slices = slices;
    FdkReport report;
    const std::vector<float> cut = reconstruct_fdk_dense(p, c.geometry, c.grid, options, &report);
    EXPECT_EQ(report.slab_count, (c.grid.size[2] + slices - 1) / slices);
    ASSERT_EQ(cut.size(), whole.size());
    EXPECT_EQ(0, std::memcmp(cut.data(), whole.data(), whole.size() * sizeof(float))) << slices << " slices";
  }
  // Two devices (here the same one twice, each with its own context and
  // queue) take slabs in turn; the sink still gets them in order.
  FdkOptions two;
  two.devices = {0, 0};
  two.max_slab_slices = 3;
  FdkReport two_report;
  const std::vector<float> shared = reconstruct_fdk_dense(p, c.geometry, c.grid, two, &two_report);
  EXPECT_EQ(two_report.devices.size(), 2U);
  EXPECT_EQ(0, std::memcmp(shared.data(), whole.data(), whole.size() * sizeof(float)));
  // A device memory limit too small for the whole volume cuts it too.
  FdkOptions tight;
  tight.device_memory_limit = whole_report.device_bytes_per_slab - c.grid.voxel_count() * sizeof(float) / 2;
  FdkReport report;
  const std::vector<float> cut = reconstruct_fdk_dense(p, c.geometry, c.grid, tight, &report);
  EXPECT_GE(report.slab_count, 2U);
  EXPECT_LE(report.device_bytes_per_slab, tight.device_memory_limit);
  EXPECT_EQ(0, std::memcmp(cut.data(), whole.data(), whole.size() * sizeof(float)));
}

// On a CPU device the device memory is the host's: a dense slab plan holds,
// within the budget, the slabs that come back to the host and wait there
// (one device: one being built, two queued, one consumed), not one slab
// (issue 23: at 2048³ the detection preview's slabs took 2 GB of a 512 MB
// share).
TEST(Fdk, CpuDeviceBudgetHoldsTheHostSlabsInFlight) {
  SmallCase c = small_case(2 * M_PI, 40, 1.0, 3.0);
  // Slices large against the detector's buffers, so that the slab decides.
  c.grid = VolumeGrid::centred({128, 128, 48}, Vec3{0.25, 0.25, 0.5});
  InMemoryProjections p = project_ball(c.geometry, {0, 0, 0}, 12.0, 0.02);
  FdkReport whole_report;
  const std::vector<float> whole = reconstruct_fdk_dense(p, c.geometry, c.grid, {}, &whole_report);
  const std::uint64_t slice_bytes = std::uint64_t{c.grid.size[0]} * c.grid.size[1] * sizeof(float);
  FdkOptions options;
  options.cpu_device_memory_limit = whole_report.device_bytes_per_slab / 2;
  FdkReport report;
  const std::vector<float> cut = reconstruct_fdk_dense(p, c.geometry, c.grid, options, &report);
  ASSERT_FALSE(report.devices.empty());
  EXPECT_LE(report.device_bytes_per_slab, options.cpu_device_memory_limit);
  // One CPU device: a slab being built, one waiting, one being consumed.
  EXPECT_LE(3 * report.slab_slices * slice_bytes, options.cpu_device_memory_limit);
  EXPECT_GE(report.slab_count, 2U);
  EXPECT_EQ(0, std::memcmp(cut.data(), whole.data(), whole.size() * sizeof(float)));
}

// The host memory the filtered rows can take, which recon gives a CPU
// device's slabs the rest of: every row of every view (rows in pairs) when
// they fit the budget, else the budget in whole pairs, never less than a
// run holds, and with the disk bound adding up to every row.
TEST(Fdk, FilteredRowsHostBoundIsWhatTheRowsCanTake) {
  SmallCase c = small_case(2 * M_PI, 40, 1.0, 3.0);
  c.geometry.detector.rows = 39;  // an odd count: the last pair is half used, wholly held
  const std::uint64_t pair_bytes = 40ULL * 2 * c.geometry.detector.columns * sizeof(float);
  const std::uint64_t every_row = 20 * pair_bytes;
  FdkOptions options;
  options.filtered_rows_memory_limit = 1ULL << 30;
  EXPECT_EQ(filtered_rows_host_bound(c.geometry, options), every_row);
  EXPECT_EQ(filtered_rows_disk_bound(c.geometry, options), 0U);
  options.filtered_rows_memory_limit = 5 * pair_bytes / 2;
  EXPECT_EQ(filtered_rows_host_bound(c.geometry, options), 2 * pair_bytes);
  EXPECT_EQ(filtered_rows_disk_bound(c.geometry, options), 18 * pair_bytes);
  FdkReport report;
  InMemoryProjections p = project_ball(c.geometry, {0, 0, 0}, 12.0, 0.02);
  options.max_slab_slices = 3;
  reconstruct_fdk_dense(p, c.geometry, c.grid, options, &report);
  EXPECT_GT(report.filtered_rows_host_bytes, 0U);
  EXPECT_LE(report.filtered_rows_host_bytes, filtered_rows_host_bound(c.geometry, options));
  options.cache_filtered_rows = false;
  EXPECT_EQ(filtered_rows_host_bound(c.geometry, options), 0U);
}

TEST(Fdk, PartsOfAGridMatchTheWhole) {
  SmallCase c = small_case(2 * M_PI, 40, 1.0, 3.0);
  InMemoryProjections p = project_ball(c.geometry, {1, 2, -3}, 12.0, 0.02);
  const std::vector<float> whole = reconstruct_fdk_dense(p, c.geometry, c.grid);
  FdkReconstructor reconstructor(p, c.geometry);
  // A coarse grid first: the reconstructor is reused across grids.
  const VolumeGrid coarse = VolumeGrid::centred({6, 6, 5}, 6.0);
  std::vector<float> low(coarse.voxel_count());
  reconstructor.reconstruct(coarse, [&](std::uint32_t k0, std::uint32_t k1, const float* d) {
    std::copy(d, d + 36 * (k1 - k0), low.begin() + 36 * k0);
  });
  EXPECT_GT(low[(2 * 6 + 3) * 6 + 3], 0.01F);  // the ball shows at low resolution
  const std::size_t slice = std::size_t{c.grid.size[0]} * c.grid.size[1];
  for (auto [k0, k1] : {std::pair<std::uint32_t, std::uint32_t>{0, 3}, {5, 6}, {7, 20}}) {
    std::vector<float> part;
    std::uint32_t next = k0;
    reconstructor.reconstruct(
        c.grid,
        [&](std::uint32_t a, std::uint32_t b, const float* d) {
          EXPECT_EQ(a, next);
          next = b;
          part.insert(part.end(), d, d + slice * (b - a));
        },
        k0, k1);
    EXPECT_EQ(next, k1);
    ASSERT_EQ(part.size(), slice * (k1 - k0));
    EXPECT_EQ(0, std::memcmp(part.data(), whole.data() + slice * k0, part.size() * sizeof(float)))
        << "slices " << k0 << ".." << k1;
  }
}

TEST(Fdk, ReducedScanMergesPixelsWhereTheyLie) {
  // 49 columns: binning by 2 drops the last one, which moves the centre.
  ScanGeometry g = circular_scan({49, 30, 0.7, 0.9}, 10, 300.0, 600.0, 2 * M_PI, 0.2, 3.0, -2.0);
  g.views[4].source_offset_u = 1.5;
  const ScanGeometry r = reduce_scan(g, 3, 2);
  ASSERT_EQ(r.view_count(), 4U);
  ASSERT_EQ(r.detector.columns, 24);
  ASSERT_EQ(r.detector.rows, 15);
  for (std::size_t v = 0; v < r.view_count(); ++v)
    for (int c : {0, 7, 23})
      for (int row : {0, 14}) {
        Vec3 mean{0, 0, 0};
        for (int y = 0; y < 2; ++y)
          for (int x = 0; x < 2; ++x) {
            const Vec3 p = g.pixel_position(v * 3, 2 * c + x, 2 * row + y);
            for (int a = 0; a < 3; ++a) mean[a] += 0.25 * p[a];
          }
        const Vec3 got = r.pixel_position(v, c, row);
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(got[a], mean[a], 1e-9);
      }
  InMemoryProjections p(49, 30, 10);
  for (std::size_t i = 0; i < p.data().size(); ++i) p.data()[i] = static_cast<float>((i * 37) % 101);
  ReducedProjections reduced(p, 3, 2);
  std::vector<float> band(24 * 5);
  reduced.read_rows(2, 3, 8, band.data());
  for (int row = 3; row < 8; ++row)
    for (int c = 0; c < 24; ++c) {
      const float* image = p.view_data(6);
      const float sum = image[(2 * row) * 49 + 2 * c] + image[(2 * row) * 49 + 2 * c + 1] +
                        image[(2 * row + 1) * 49 + 2 * c] + image[(2 * row + 1) * 49 + 2 * c + 1];
      EXPECT_FLOAT_EQ(band[(row - 3) * 24 + c], sum / 4);
    }
}

// A source that counts the requests it is asked (an HDF5 source's each
// cost a round trip to its child process).
class CountingProjections : public ProjectionSource {
 public:
  explicit CountingProjections(ProjectionSource& source) : source_(source) {}
  int columns() const override { return source_.columns(); }
  int rows() const override { return source_.rows(); }
  std::size_t view_count() const override { return source_.view_count(); }
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override {
    ++requests;
    source_.read_rows(view, row_begin, row_end, out);
  }
  int requests = 0;

 private:
  ProjectionSource& source_;
};

TEST(Fdk, ReducedScanAsksForRunsOfRows) {
  // 4096 columns binned by 2: runs of 128 binned rows (4 MiB of source
  // rows); a band of 300 binned rows takes 3 requests, not 300, and every
  // pixel is still the mean of its four, across the runs' boundaries.
  InMemoryProjections p(4096, 620, 2);
  for (std::size_t i = 0; i < p.data().size(); ++i) p.data()[i] = static_cast<float>((i * 37) % 1009);
  CountingProjections counted(p);
  ReducedProjections reduced(counted, 1, 2);
  std::vector<float> band(2048 * 300);
  reduced.read_rows(1, 5, 305, band.data());
  EXPECT_EQ(counted.requests, 3);
  const float* image = p.view_data(1);
  for (int row = 5; row < 305; ++row)
    for (int c = 0; c < 2048; c += 97) {
      const float sum = image[(2 * row) * 4096 + 2 * c] + image[(2 * row) * 4096 + 2 * c + 1] +
                        image[(2 * row + 1) * 4096 + 2 * c] + image[(2 * row + 1) * 4096 + 2 * c + 1];
      ASSERT_EQ(band[(row - 5) * 2048 + c], sum / 4) << "row " << row << " column " << c;
    }
  reduced.read_rows(0, 7, 7, band.data());  // an empty band asks for nothing
  EXPECT_EQ(counted.requests, 3);
}

TEST(Fdk, GlobalMemoryFftGivesSameBits) {
  SmallCase c = small_case(2 * M_PI, 20);
  InMemoryProjections p = project_ball(c.geometry, {0, 0, 0}, 12.0, 0.02);
  const std::vector<float> local = reconstruct_fdk_dense(p, c.geometry, c.grid);
  FdkOptions options;
  options.fft_in_global_memory = true;
  const std::vector<float> global = reconstruct_fdk_dense(p, c.geometry, c.grid, options);
  EXPECT_EQ(0, std::memcmp(local.data(), global.data(), local.size() * sizeof(float)));
}

// RTK's quality check (rtkfdktest.cxx with rtkTest.h's CheckImageQuality):
// the reconstruction is set to zero outside the field of view (voxels some
// view does not see, as RTK's FieldOfViewImageFilter does), then the mean
// absolute error and the PSNR with a peak of 2 are taken over the whole
// volume. The same figures over the field of view alone are kept too.
struct Quality {
  double mae = 0;
  double psnr = 0;
  double mae_in_view = 0;
  std::size_t voxels_in_view = 0;
};

Quality rtk_quality(const std::vector<float>& volume, const std::vector<float>& truth, const ScanGeometry& g,
                    const VolumeGrid& grid, double peak = 2.0) {
  Quality q;
  double squared = 0;
  double error_sum = 0;
  double in_view_sum = 0;
  std::size_t index = 0;
  for (std::uint32_t k = 0; k < grid.size[2]; ++k)
    for (std::uint32_t j = 0; j < grid.size[1]; ++j)
      for (std::uint32_t i = 0; i < grid.size[0]; ++i, ++index) {
        bool seen = true;
        for (std::size_t v = 0; v < g.view_count() && seen; ++v) {
          const auto p = g.project(v, grid.voxel_centre(i, j, k));
          seen = p.column >= 0 && p.column <= g.detector.columns - 1 && p.row >= 0 && p.row <= g.detector.rows - 1;
        }
        const double e = (seen ? static_cast<double>(volume[index]) : 0.0) - truth[index];
        error_sum += std::abs(e);
        squared += e * e;
        if (seen) {
          in_view_sum += std::abs(e);
          ++q.voxels_in_view;
        }
      }
  const double n = static_cast<double>(grid.voxel_count());
  q.mae = error_sum / n;
  q.psnr = 20 * std::log10(peak) - 10 * std::log10(squared / n);
  q.mae_in_view = in_view_sum / static_cast<double>(q.voxels_in_view);
  return q;
}

// RTK's rtkfdktest: Shepp–Logan at scale 116, 128³ voxels of 2 mm, 128²
// pixels of 4 mm, SID/SDD 600/1200 mm; with the detector offset (20, 15) mm.
struct SheppLoganCase {
  ScanGeometry geometry;
  VolumeGrid grid = VolumeGrid::centred({128, 128, 128}, 2.0);
  Phantom phantom = shepp_logan_3d(116.0);
  std::vector<float> truth;
  explicit SheppLoganCase(ScanGeometry g) : geometry(std::move(g)) {
    truth.resize(grid.voxel_count());
    voxelize(phantom, grid, 0, grid.size[2], truth.data());
  }
};

TEST(FdkAccuracy, SheppLoganFullScanMeetsRtkThresholds) {
  SheppLoganCase c(circular_scan({128, 128, 4.0, 4.0}, 180, 600.0, 1200.0, 2 * M_PI, 0.0, 20.0, 15.0));
  InMemoryProjections p = project_scan(c.phantom, c.geometry);
  FdkReport report;
  const std::vector<float> volume = reconstruct_fdk_dense(p, c.geometry, c.grid, {}, &report);
  EXPECT_FALSE(report.short_scan);
  const Quality q = rtk_quality(volume, c.truth, c.geometry, c.grid);
  EXPECT_GT(q.voxels_in_view, c.grid.voxel_count() / 3);
  EXPECT_LT(q.mae, 0.03);
  EXPECT_GT(q.psnr, 26.0);
  std::printf("full scan: MAE %.4f, PSNR %.2f dB (MAE %.4f over the %zu voxels in view)\n", q.mae, q.psnr,
              q.mae_in_view, q.voxels_in_view);
}

TEST(FdkAccuracy, SheppLoganShortScanWithParkerWeights) {
  // RTK's short-scan case: 110 views over 240°, which exceeds 180° plus this
  // scan's fan angle.
  SheppLoganCase c(circular_scan({128, 128, 4.0, 4.0}, 110, 600.0, 1200.0, 240.0 * M_PI / 180.0, 0.0, 20.0, 15.0));
  InMemoryProjections p = project_scan(c.phantom, c.geometry);
  FdkReport report;
  const std::vector<float> volume = reconstruct_fdk_dense(p, c.geometry, c.grid, {}, &report);
  EXPECT_TRUE(report.short_scan);
  EXPECT_TRUE(report.warnings.empty());
  const Quality q = rtk_quality(volume, c.truth, c.geometry, c.grid);
  EXPECT_LT(q.mae, 0.09);
  EXPECT_GT(q.psnr, 22.0);
  std::printf("short scan: MAE %.4f, PSNR %.2f dB (MAE %.4f over the %zu voxels in view)\n", q.mae, q.psnr,
              q.mae_in_view, q.voxels_in_view);
}

// RTK's rtkdisplaceddetectortest: the detector shifted ±120 mm (half-fan),
// 180 views over a full circle; Wang's weighting and the zero-extended
// detector must meet its thresholds (MAE ≤ 0.061, PSNR ≥ 24 dB). Without the
// weighting the same projections miss them: the test can fail.
TEST(FdkAccuracy, DisplacedDetectorMeetsRtkThresholds) {
  for (const double offset : {120.0, -120.0}) {
    SCOPED_TRACE(offset);
    SheppLoganCase c(circular_scan({128, 128, 4.0, 4.0}, 180, 600.0, 1200.0, 2 * M_PI, 0.0, offset, 0.0));
    InMemoryProjections p = project_scan(c.phantom, c.geometry);
    const DisplacedDetector displaced = analyse_displaced_detector(c.geometry);
    ASSERT_EQ(displaced.side, offset > 0 ? 1 : -1);
    EXPECT_NEAR(displaced.overlap, 134.0, 1e-9);  // 64·4 − 2 − 120 mm: the near edge's pixel centre
    const ScanGeometry wide = widen_for_displaced_detector(c.geometry, displaced);
    DisplacedDetectorProjections weighted(p, c.geometry, displaced);
    const std::vector<float> volume = reconstruct_fdk_dense(weighted, wide, c.grid);
    const Quality q = rtk_quality(volume, c.truth, wide, c.grid);
    EXPECT_GT(q.voxels_in_view, c.grid.voxel_count() * 8 / 10);  // all but the cone's corners
    EXPECT_LE(q.mae, 0.061);
    EXPECT_GE(q.psnr, 24.0);
    std::printf("displaced detector %+.0f mm: MAE %.4f, PSNR %.2f dB\n", offset, q.mae, q.psnr);
    if (offset < 0) continue;  // one side shows the weighting is needed
    const std::vector<float> unweighted = reconstruct_fdk_dense(p, c.geometry, c.grid);
    const Quality plain = rtk_quality(unweighted, c.truth, wide, c.grid);
    EXPECT_GT(plain.mae, 0.061) << "the case does not need the weighting";
    std::printf("  without weighting: MAE %.4f, PSNR %.2f dB\n", plain.mae, plain.psnr);
  }
}

TEST(FdkAccuracy, PoissonNoiseIsTamedByWindows) {
  // Shepp–Logan's densities are 1/mm-scale numbers whose line integrals no
  // photon would cross; at 1 % of them (a plastic-like 0.02/mm) 10⁴ photons
  // per pixel give realistic noise.
  SheppLoganCase c(circular_scan({128, 128, 4.0, 4.0}, 180, 600.0, 1200.0, 2 * M_PI));
  for (Shape& shape : c.phantom.shapes) shape.density *= 0.01;
  for (float& t : c.truth) t *= 0.01F;
  InMemoryProjections clean = project_scan(c.phantom, c.geometry);
  InMemoryProjections noisy = clean;
  add_poisson_noise(noisy.data().data(), noisy.data().size(), 1e4, 42);
  // The noise in the volume: noisy minus noiseless reconstruction, RMS over
  // the central cylinder. Its variance goes with ∫ f² W(f)² df, which each
  // window in this list makes smaller than the one before; Hann's is 0.09 of
  // Ram-Lak's, an RMS ratio of 0.30, lifted somewhat because bilinear
  // interpolation damps the highest frequencies under every window.
  double ram_lak_noise = 0;
  double previous = 1e300;
  for (RampWindow window : {RampWindow::RamLak, RampWindow::SheppLogan, RampWindow::Cosine, RampWindow::Hann}) {
    FdkOptions options;
    options.window = window;
    const std::vector<float> a = reconstruct_fdk_dense(noisy, c.geometry, c.grid, options);
    const std::vector<float> b = reconstruct_fdk_dense(clean, c.geometry, c.grid, options);
    double squared = 0;
    std::size_t count = 0;
    for (std::uint32_t k = 32; k < 96; ++k)
      for (std::uint32_t j = 0; j < 128; ++j)
        for (std::uint32_t i = 0; i < 128; ++i) {
          const double x = i - 63.5, y = j - 63.5;
          if (x * x + y * y > 50.0 * 50.0) continue;
          const std::size_t n = (std::size_t{k} * 128 + j) * 128 + i;
          squared += (static_cast<double>(a[n]) - b[n]) * (static_cast<double>(a[n]) - b[n]);
          ++count;
        }
    const double noise = std::sqrt(squared / static_cast<double>(count));
    const Quality q = rtk_quality(a, c.truth, c.geometry, c.grid, 0.02);
    SCOPED_TRACE(ramp_window_name(window));
    EXPECT_LT(noise, previous);
    previous = noise;
    if (window == RampWindow::RamLak) ram_lak_noise = noise;
    // The densities are 1 % of RTK's, so its threshold scales with them,
    // with room for the noise.
    EXPECT_LT(q.mae, 0.03 * 0.01 * 1.5);
    std::printf("noisy (10^4 photons), %s: RMS noise %.3g /mm, MAE %.3g, PSNR %.2f dB\n", ramp_window_name(window),
                noise, q.mae, q.psnr);
  }
  EXPECT_LT(previous / ram_lak_noise, 0.5);
  EXPECT_GT(previous / ram_lak_noise, 0.3);
}

TEST(FdkAccuracy, TooShortArcIsReported) {
  ScanGeometry g = circular_scan({64, 32, 4.0, 4.0}, 40, 600.0, 1200.0, 190.0 * M_PI / 180.0);
  InMemoryProjections p(64, 32, 40);
  FdkReport report;
  reconstruct_fdk_dense(p, g, VolumeGrid::centred({16, 16, 8}, 4.0), {}, &report);
  EXPECT_TRUE(report.short_scan);
  ASSERT_EQ(report.warnings.size(), 1U);
  EXPECT_NE(report.warnings[0].find("shorter than 180"), std::string::npos) << report.warnings[0];
}

}  // namespace
}  // namespace ivol::recon
