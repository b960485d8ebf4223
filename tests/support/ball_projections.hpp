// Exact line integrals of a uniform ball (density × chord length), written
// independently of the phantom library, so that FDK tests compare against
// something they did not compute with the code under test.
#pragma once

#include <cmath>
#include <cstddef>

#include "ivol/recon/fdk.hpp"

namespace ivol::recon::test {

inline InMemoryProjections project_ball(const ScanGeometry& g, const Vec3& centre, double radius, double density) {
  InMemoryProjections p(g.detector.columns, g.detector.rows, g.view_count());
  for (std::size_t v = 0; v < g.view_count(); ++v) {
    const Vec3 s = g.source_position(v);
    for (int r = 0; r < g.detector.rows; ++r)
      for (int c = 0; c < g.detector.columns; ++c) {
        const Vec3 e = g.pixel_position(v, c, r);
        Vec3 dir{e[0] - s[0], e[1] - s[1], e[2] - s[2]};
        const double len = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        for (double& x : dir) x /= len;
        const Vec3 oc{s[0] - centre[0], s[1] - centre[1], s[2] - centre[2]};
        const double b = oc[0] * dir[0] + oc[1] * dir[1] + oc[2] * dir[2];
        const double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - radius * radius;
        const double disc = b * b - cc;
        p.view_data(v)[static_cast<std::size_t>(r) * g.detector.columns + c] =
            disc > 0 ? static_cast<float>(2.0 * std::sqrt(disc) * density) : 0.0F;
      }
  }
  return p;
}

}  // namespace ivol::recon::test
