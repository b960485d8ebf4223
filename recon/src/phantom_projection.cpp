// Projections, photon noise and voxelization of analytic phantoms.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <random>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#include "ivol/recon/phantom.hpp"
#include "phantom_shapes.hpp"

namespace ivol::recon {
namespace {

using phantom_detail::chord_fraction;
using phantom_detail::dot;
using phantom_detail::intersect;
using phantom_detail::Interval;
using phantom_detail::minus;
using phantom_detail::prepare_all;
using phantom_detail::Prepared;

// Runs task(i) for i in [0, count) on up to `threads` threads (0: one per
// hardware thread); rethrows the first exception a task threw.
template <typename Task>
void run_parallel(std::size_t count, unsigned threads, const Task& task) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = static_cast<unsigned>(std::min<std::size_t>(threads, count));
  std::atomic<std::size_t> next{0};
  std::exception_ptr failure;
  std::mutex failure_mutex;
  auto worker = [&] {
    try {
      for (std::size_t i = next++; i < count; i = next++) task(i);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      next = count;
    }
  };
  std::vector<std::thread> pool;
  try {
    for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker);
  } catch (const std::system_error&) {  // no more threads (a process limit): fewer share the work
  }
  worker();
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
}

void check_supersampling(int supersampling) {
  if (supersampling < 1 || supersampling > 64)
    throw std::invalid_argument("phantom: supersampling must be 1 to 64, not " + std::to_string(supersampling));
}

// Sub-sample k of s along one pixel or voxel axis, in units of the pitch from
// its centre.
double sub_offset(int k, int s) { return (k + 0.5) / s - 0.5; }

void project_prepared(const std::vector<Prepared>& shapes, const ScanGeometry& g, std::size_t view, float* image,
                      int s) {
  const int columns = g.detector.columns;
  const int rows = g.detector.rows;
  const Vec3 source = g.source_position(view);
  // pixel_position is affine in (column, row).
  const Vec3 p00 = g.pixel_position(view, 0.0, 0.0);
  const Vec3 du = minus(g.pixel_position(view, 1.0, 0.0), p00);
  const Vec3 dv = minus(g.pixel_position(view, 0.0, 1.0), p00);
  std::vector<double> sum(static_cast<std::size_t>(columns) * rows, 0.0);
  for (const Prepared& shape : shapes) {
    // Pixels the shape can cover: the cube about its bounding sphere is
    // convex, so its shadow lies in the box of its projected corners when
    // the whole cube is in front of the source; otherwise every pixel.
    int c0 = 0, c1 = columns - 1, r0 = 0, r1 = rows - 1;
    const double r = std::sqrt(shape.bound_squared);
    double cmin = std::numeric_limits<double>::infinity(), cmax = -cmin, rmin = cmin, rmax = -cmin;
    bool in_front = true;
    for (int corner = 0; corner < 8 && in_front; ++corner) {
      const Vec3 p{shape.centre[0] + ((corner & 1) ? r : -r), shape.centre[1] + ((corner & 2) ? r : -r),
                   shape.centre[2] + ((corner & 4) ? r : -r)};
      const ScanGeometry::Projected q = g.project(view, p);
      in_front = q.magnification > 0.0 && std::isfinite(q.magnification);
      cmin = std::min(cmin, q.column), cmax = std::max(cmax, q.column);
      rmin = std::min(rmin, q.row), rmax = std::max(rmax, q.row);
    }
    if (in_front) {
      if (cmax < -1.0 || rmax < -1.0 || cmin > columns || rmin > rows) continue;
      c0 = std::max(0, static_cast<int>(std::floor(cmin)));
      c1 = std::min(columns - 1, static_cast<int>(std::ceil(cmax)));
      r0 = std::max(0, static_cast<int>(std::floor(rmin)));
      r1 = std::min(rows - 1, static_cast<int>(std::ceil(rmax)));
    }
    for (int j = r0; j <= r1; ++j)
      for (int i = c0; i <= c1; ++i) {
        double total = 0.0;
        for (int b = 0; b < s; ++b)
          for (int a = 0; a < s; ++a) {
            const double x = i + sub_offset(a, s);
            const double y = j + sub_offset(b, s);
            const Vec3 d{p00[0] + x * du[0] + y * dv[0] - source[0], p00[1] + x * du[1] + y * dv[1] - source[1],
                         p00[2] + x * du[2] + y * dv[2] - source[2]};
            const double length_squared = dot(d, d);
            total += chord_fraction(shape, source, d, length_squared) * std::sqrt(length_squared);
          }
        sum[static_cast<std::size_t>(j) * columns + i] += total;
      }
  }
  const double scale = 1.0 / (static_cast<double>(s) * s);
  for (std::size_t k = 0; k < sum.size(); ++k) image[k] = static_cast<float>(sum[k] * scale);
}

void voxelize_slice(const std::vector<Prepared>& shapes, const VolumeGrid& g, std::uint32_t k, float* out, int s) {
  const std::uint32_t nx = g.size[0];
  std::vector<double> row(nx);
  const Vec3 along_x{1.0, 0.0, 0.0};
  for (std::uint32_t j = 0; j < g.size[1]; ++j) {
    std::fill(row.begin(), row.end(), 0.0);
    for (int c = 0; c < s; ++c)
      for (int b = 0; b < s; ++b) {
        // The line of sub-samples along x at this (y, z), t = x − origin_x.
        const Vec3 start = g.voxel_centre(0.0, j + sub_offset(b, s), k + sub_offset(c, s));
        for (const Prepared& shape : shapes) {
          const Vec3 relative = minus(start, shape.centre);
          if (relative[1] * relative[1] + relative[2] * relative[2] > shape.bound_squared) continue;
          const Interval iv = intersect(shape, relative, along_x);
          if (!(iv.t0 <= iv.t1)) continue;
          for (int a = 0; a < s; ++a) {
            // Sub-samples at x = (i + offset)·voxel_size in [t0, t1].
            const double first = std::ceil(iv.t0 / g.voxel_size[0] - sub_offset(a, s));
            const double last = std::floor(iv.t1 / g.voxel_size[0] - sub_offset(a, s));
            const double i0 = std::max(first, 0.0);
            const double i1 = std::min(last, static_cast<double>(nx) - 1.0);
            for (double i = i0; i <= i1; i += 1.0) row[static_cast<std::size_t>(i)] += shape.density;
          }
        }
      }
    const double scale = 1.0 / (static_cast<double>(s) * s * s);
    for (std::uint32_t i = 0; i < nx; ++i) out[std::size_t{j} * nx + i] = static_cast<float>(row[i] * scale);
  }
}

}  // namespace

void project_view(const Phantom& phantom, const ScanGeometry& geometry, std::size_t view, float* image,
                  int supersampling) {
  check_supersampling(supersampling);
  geometry.validate();
  if (view >= geometry.view_count())
    throw std::out_of_range("phantom: view " + std::to_string(view) + " of a scan of " +
                            std::to_string(geometry.view_count()));
  project_prepared(prepare_all(phantom), geometry, view, image, supersampling);
}

InMemoryProjections project_scan(const Phantom& phantom, const ScanGeometry& geometry, int supersampling,
                                 unsigned threads) {
  check_supersampling(supersampling);
  geometry.validate();
  const std::vector<Prepared> shapes = prepare_all(phantom);
  InMemoryProjections out(geometry.detector.columns, geometry.detector.rows, geometry.view_count());
  run_parallel(geometry.view_count(), threads,
               [&](std::size_t view) { project_prepared(shapes, geometry, view, out.view_data(view), supersampling); });
  return out;
}

void add_poisson_noise(float* line_integrals, std::size_t count, double incident_photons, std::uint64_t seed) {
  if (!(incident_photons > 0.0) || !std::isfinite(incident_photons))
    throw std::invalid_argument("poisson noise: the incident photon count must be positive and finite");
  std::mt19937_64 rng(seed);
  for (std::size_t n = 0; n < count; ++n) {
    const double expected = incident_photons * std::exp(-static_cast<double>(line_integrals[n]));
    if (!std::isfinite(expected))
      throw std::invalid_argument("poisson noise: line integral " + std::to_string(n) +
                                  " is not finite or too negative");
    double counted = 0.0;
    if (expected > 0.0) counted = static_cast<double>(std::poisson_distribution<long long>(expected)(rng));
    // A pixel that counted no photon would have an infinite line integral;
    // it is taken to have counted half a photon, which bounds the result
    // by log(2·I0).
    line_integrals[n] = static_cast<float>(-std::log(std::max(counted, 0.5) / incident_photons));
  }
}

void voxelize(const Phantom& phantom, const VolumeGrid& grid, std::uint32_t k_begin, std::uint32_t k_end, float* out,
              int supersampling) {
  check_supersampling(supersampling);
  grid.validate();
  if (k_begin > k_end || k_end > grid.size[2])
    throw std::out_of_range("voxelize: slices " + std::to_string(k_begin) + ".." + std::to_string(k_end) +
                            " are outside a grid of " + std::to_string(grid.size[2]));
  const std::vector<Prepared> shapes = prepare_all(phantom);
  const std::size_t slice = std::size_t{grid.size[0]} * grid.size[1];
  run_parallel(k_end - k_begin, 0, [&](std::size_t n) {
    voxelize_slice(shapes, grid, k_begin + static_cast<std::uint32_t>(n), out + n * slice, supersampling);
  });
}

}  // namespace ivol::recon
