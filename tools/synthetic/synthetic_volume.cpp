#include "synthetic_volume.hpp"

#include <cmath>
#include <random>
#include <thread>

namespace ivol::synthetic {
namespace {

// Fraction of the object at normalised position (u, v, w) in [-1, 1]^3.
float occupancy(Object object, double u, double v, double w) {
  switch (object) {
    case Object::PencilHolder: {
      const double r = std::sqrt(u * u + v * v);
      const bool wall = r > 0.52 && r < 0.60 && w > -0.75 && w < 0.75;
      const bool base = r < 0.60 && w > -0.75 && w < -0.65;
      return (wall || base) ? 1.0f : 0.0f;
    }
    case Object::Board: {
      const bool board = std::fabs(w) < 0.04 && std::fabs(u) < 0.8 && std::fabs(v) < 0.6;
      // A grid of small components on top of the board.
      const double cu = std::fmod(u + 1.0, 0.25) - 0.125;
      const double cv = std::fmod(v + 1.0, 0.25) - 0.125;
      const bool part = w >= 0.04 && w < 0.12 && std::fabs(cu) < 0.04 && std::fabs(cv) < 0.03 && std::fabs(u) < 0.75 &&
                        std::fabs(v) < 0.55;
      return (board || part) ? 1.0f : 0.0f;
    }
    case Object::Pipe: {
      const double r = std::sqrt(u * u + w * w);
      return (r > 0.40 && r < 0.44 && std::fabs(v) < 0.9) ? 1.0f : 0.0f;
    }
  }
  return 0.0f;
}

}  // namespace

const char* object_name(Object object) {
  switch (object) {
    case Object::PencilHolder:
      return "pencil-holder";
    case Object::Board:
      return "board";
    case Object::Pipe:
      return "pipe";
  }
  return "unknown";
}

bool parse_object(const std::string& name, Object& out) {
  for (Object o : {Object::PencilHolder, Object::Board, Object::Pipe})
    if (name == object_name(o)) {
      out = o;
      return true;
    }
  return false;
}

std::vector<float> make_volume(const VolumeSpec& spec) {
  const Dims& d = spec.dims;
  std::vector<float> volume(voxel_count(d));
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (std::uint32_t z = t; z < d[2]; z += threads) {
        // One generator per slice: the volume does not depend on the thread count.
        std::mt19937_64 rng(spec.seed * 0x9E3779B97F4A7C15ull + z);
        std::normal_distribution<float> noise(0.0f, spec.noise_sigma > 0 ? spec.noise_sigma : 1.0f);
        const double w = (z + 0.5) / d[2] * 2.0 - 1.0;
        for (std::uint32_t y = 0; y < d[1]; ++y) {
          const double v = (y + 0.5) / d[1] * 2.0 - 1.0;
          float* row = volume.data() + (std::uint64_t{z} * d[1] + y) * d[0];
          for (std::uint32_t x = 0; x < d[0]; ++x) {
            const double u = (x + 0.5) / d[0] * 2.0 - 1.0;
            float value = spec.material * occupancy(spec.object, u, v, w);
            if (spec.noise_sigma > 0) value += noise(rng);
            row[x] = value;
          }
        }
      }
    });
  for (auto& th : pool) th.join();
  return volume;
}

}  // namespace ivol::synthetic
