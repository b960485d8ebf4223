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
#include "ivol/structures.hpp"

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
  // A slab of more than 32 slices: summed by columns, not as fine tasks.
  list.push_back({"thick slab, columns", full, VolumeGrid::centred({20, 18, 40}, 0.7), 0});
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

// A structure's blocks (fdk_backproject_fine on OpenCL devices, the native
// backprojector on CPU devices with AVX-512F) get the same bits either way,
// and its fine voxels the dense reconstruction's: octrees with full-
// resolution bricks around the ball and coarse leaves elsewhere, on every
// case above (the strip and the gather path, thin slabs, a short scan).
TEST(FdkNative, StructureBlocksSameBitsAsTheOpenClKernel) {
  if (!native_backprojection_supported())
    GTEST_SKIP() << "this CPU lacks AVX-512F: the native backprojector is not used here";
  const int cpu = cpu_device();
  ASSERT_GE(cpu, 0) << "no OpenCL CPU device (install pocl-opencl-icd)";
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    InMemoryProjections p = project_ball(c.geometry, {1.0, -2.0, 1.5}, 9.0, 0.02);
    NeedMask mask;
    mask.dims = Dims{c.grid.size[0], c.grid.size[1], c.grid.size[2]};
    mask.factor = 1;
    mask.cells = mask.dims;
    mask.need.resize(c.grid.voxel_count());
    for (std::uint32_t k = 0; k < mask.dims[2]; ++k)
      for (std::uint32_t j = 0; j < mask.dims[1]; ++j)
        for (std::uint32_t i = 0; i < mask.dims[0]; ++i) {
          const Vec3 at = c.grid.voxel_centre(i, j, k);
          const double r = std::hypot(at[0] - 1.0, at[1] + 2.0, at[2] - 1.5);
          mask.need[(std::size_t{k} * mask.dims[1] + j) * mask.dims[0] + i] = r < 10.0 ? 1 : 0;
        }
    FdkOptions kernel;
    kernel.devices = {cpu};
    kernel.native_cpu_backprojection = false;
    kernel.max_slab_slices = c.max_slab_slices;
    FdkOptions native = kernel;
    native.native_cpu_backprojection = true;
    auto by_kernel = generate_structure(StructureKind::Octree, mask);
    auto by_native = generate_structure(StructureKind::Octree, mask);
    FdkReconstructor(p, c.geometry, kernel).reconstruct_structure(c.grid, *by_kernel);
    const FdkReport report = FdkReconstructor(p, c.geometry, native).reconstruct_structure(c.grid, *by_native);
    ASSERT_EQ(report.backprojectors, std::vector<std::string>{"native-avx512"});
    const std::vector<float>& a = by_kernel->values();
    const std::vector<float>& b = by_native->values();
    ASSERT_EQ(a.size(), b.size());
    ASSERT_LT(a.size(), c.grid.voxel_count()) << "coarse leaves too";
    std::size_t differing = 0;
    for (std::size_t i = 0; i < a.size(); ++i) differing += std::memcmp(&a[i], &b[i], sizeof(float)) != 0;
    EXPECT_EQ(differing, 0U) << "of " << a.size() << " structure voxels";
    // Fine voxels: the dense reconstruction's bits (native both).
    const std::vector<float> dense = reconstruct_fdk_dense(p, c.geometry, c.grid, native);
    std::size_t fine = 0;
    for (const Brick& brick : by_native->bricks()) {
      if (brick.voxel[0] != 1 || brick.voxel[1] != 1 || brick.voxel[2] != 1) continue;
      for (std::uint32_t z = 0; z < brick.count[2]; ++z)
        for (std::uint32_t y = 0; y < brick.count[1]; ++y)
          for (std::uint32_t x = 0; x < brick.count[0]; ++x, ++fine) {
            const float value = b[brick.first_value + (std::uint64_t{z} * brick.count[1] + y) * brick.count[0] + x];
            const std::size_t at =
                (std::size_t{brick.origin[2] + z} * c.grid.size[1] + brick.origin[1] + y) * c.grid.size[0] +
                brick.origin[0] + x;
            ASSERT_EQ(0, std::memcmp(&value, &dense[at], sizeof(float))) << "voxel " << at;
          }
    }
    EXPECT_GT(fine, 1000U);
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
