// Built-in synthetic CT-like volumes for the demo, the tests and the
// benchmarks: industrial-like objects in air, with noise like a reconstruction
// has. Not a substitute for reconstructed phantoms (recon/ brings those).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol::synthetic {

enum class Object {
  PencilHolder,  // hollow cylinder with a base (the paper's Figure 3)
  Board,         // a flat board with small components
  Pipe,          // a thin-walled tube
};

struct VolumeSpec {
  Dims dims{256, 256, 256};
  Object object = Object::PencilHolder;
  float material = 0.05f;      // linear attenuation of the object, 1/mm
  float noise_sigma = 0.002f;  // Gaussian noise everywhere, 1/mm (0: none)
  std::uint64_t seed = 1;
};

const char* object_name(Object object);
bool parse_object(const std::string& name, Object& out);

// Linear attenuation in 1/mm, [z][y][x] with x fastest.
std::vector<float> make_volume(const VolumeSpec& spec);

}  // namespace ivol::synthetic
