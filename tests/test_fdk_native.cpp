// The native CPU backprojector (recon/src/fdk_native_backproject.cpp) gives
// the OpenCL kernel's bits on the same CPU device, and both stay within
// float round-off of a double-precision reference, on scans of a ball whose
// line integrals are exact: full and short scans, detector offsets, slabs
// cut at sizes that are not whole vector lanes, and detectors fine enough
// that sixteen voxels along z span more rows than one strip (the gather path).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "ball_projections.hpp"
#include "ivol/recon/fdk.hpp"
#include "ivol/recon/fdk_reference.hpp"

namespace ivol::recon {
namespace {

using test::project_ball;

// The first CPU device, which both paths then share.
int cpu_device() {
  for (const DeviceInfo& d : list_devices())
    if (!d.is_gpu) return d.index;
  return -1;
}

struct Case {
  const char* name;
  ScanGeometry geometry;
  VolumeGrid grid;
  std::uint32_t max_slab_slices;
};

std::vector<Case> cases() {
  std::vector<Case> list;
  // About 1.9 detector rows per slice: sixteen slices span up to 29 rows,
  // just within one strip.
  ScanGeometry full = circular_scan({48, 40, 1.6, 1.6}, 60, 300.0, 600.0, 2 * M_PI, 0.3, 2.0, -1.5);
  full.views[3].source_offset_u = 1.0;  // one odd view
  list.push_back({"full scan, offsets", full, VolumeGrid::centred({24, 22, 20}, 1.5), 0});
  list.push_back({"short scan (Parker)", circular_scan({48, 40, 1.6, 1.6}, 50, 300.0, 600.0, M_PI * 1.3, 0.3),
                  VolumeGrid::centred({21, 24, 19}, 1.5), 0});
  // Coarse detector rows: every sixteen slices take the strip.
  list.push_back({"coarse rows, thin slabs", circular_scan({48, 24, 1.6, 3.2}, 40, 300.0, 600.0, 2 * M_PI, 0.1),
                  VolumeGrid::centred({20, 20, 37}, 1.0), 5});
  // Fine detector rows (7.5 per slice): the gather path, and the strip where
  // the rows are clamped at the band's ends.
  list.push_back({"fine rows", circular_scan({96, 160, 0.8, 0.4}, 30, 300.0, 600.0, 2 * M_PI),
                  VolumeGrid::centred({17, 18, 20}, 1.5), 0});
  return list;
}

TEST(FdkNative, SameBitsAsTheOpenClKernel) {
  if (!native_backprojection_supported())
    GTEST_SKIP() << "this CPU lacks AVX-512F: the native backprojector is not used here";
  const int cpu = cpu_device();
  ASSERT_GE(cpu, 0) << "no OpenCL CPU device (install pocl-opencl-icd)";
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    InMemoryProjections p = project_ball(c.geometry, {1.0, -2.0, 1.5}, 9.0, 0.02);
    FdkOptions kernel;
    kernel.devices = {cpu};
    kernel.native_cpu_backprojection = false;
    kernel.max_slab_slices = c.max_slab_slices;
    FdkOptions native = kernel;
    native.native_cpu_backprojection = true;
    FdkReport kernel_report, native_report;
    const std::vector<float> a = reconstruct_fdk_dense(p, c.geometry, c.grid, kernel, &kernel_report);
    const std::vector<float> b = reconstruct_fdk_dense(p, c.geometry, c.grid, native, &native_report);
    ASSERT_EQ(kernel_report.backprojectors, std::vector<std::string>{"opencl"});
    ASSERT_EQ(native_report.backprojectors, std::vector<std::string>{"native-avx512"});
    ASSERT_EQ(a.size(), b.size());
    std::size_t differing = 0;
    float worst = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
      if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0) {
        ++differing;
        worst = std::max(worst, std::abs(a[i] - b[i]));
      }
    EXPECT_EQ(differing, 0U) << "of " << a.size() << " voxels; worst difference " << worst;
    EXPECT_GT(*std::max_element(b.begin(), b.end()), 0.01F) << "the ball is reconstructed";
  }
}

TEST(FdkNative, MatchesDoubleReference) {
  if (!native_backprojection_supported())
    GTEST_SKIP() << "this CPU lacks AVX-512F: the native backprojector is not used here";
  const int cpu = cpu_device();
  ASSERT_GE(cpu, 0);
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    InMemoryProjections p = project_ball(c.geometry, {1.0, -2.0, 1.5}, 9.0, 0.02);
    const std::vector<double> reference = reconstruct_fdk_reference(p, c.geometry, c.grid, RampWindow::Hann, 0.9);
    FdkOptions options;
    options.devices = {cpu};
    options.window = RampWindow::Hann;
    options.cutoff = 0.9;
    options.max_slab_slices = c.max_slab_slices;
    FdkReport report;
    const std::vector<float> native = reconstruct_fdk_dense(p, c.geometry, c.grid, options, &report);
    ASSERT_EQ(report.backprojectors, std::vector<std::string>{"native-avx512"});
    double scale = 0, worst = 0;
    for (std::size_t i = 0; i < native.size(); ++i) {
      scale = std::max(scale, std::abs(reference[i]));
      worst = std::max(worst, std::abs(native[i] - reference[i]));
    }
    ASSERT_GT(scale, 0.01);
    EXPECT_LT(worst / scale, 2e-5) << "worst difference " << worst << " of " << scale;
  }
}

}  // namespace
}  // namespace ivol::recon
