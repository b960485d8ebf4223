// Building a streaming writer's slabs away from the writer.
//
// A StreamingOctreeWriter builds each slab's subtrees when it is given the
// slab's samples. OctreeSlabBuilder builds the same subtrees without a
// writer, as bytes that can travel (another process, another node), and
// StreamingOctreeWriter::add_built_slab takes them: the effect is exactly
// that of add_slab with the same samples and keep mask, so the file is the
// same bit for bit. A distributed reconstruction uses it to build each slab
// on the rank that reconstructed it (docs/distributed.md): what travels is
// the built octree (stored values, node words, coarsened regions as one
// value), not float32 samples.
#pragma once

#include <cstdint>
#include <vector>

#include "ivol/streaming_writer.hpp"

namespace ivol {

// One slab's subtrees, as bytes (see libformat/src/slab_subtrees.hpp): they
// say which slab of which layout they are, so a writer refuses them when
// they do not fit.
struct BuiltSlab {
  std::vector<std::uint8_t> bytes;
};

class OctreeSlabBuilder {
 public:
  // The same dims and options as the writer that will take the slabs (its
  // slab thickness, encoding, value scale and offset; write options unused).
  OctreeSlabBuilder(const Dims& dims, const StreamingOptions& options);

  std::uint32_t slab_slices() const;
  std::uint32_t slab_count() const;
  // Slices first .. first + count of slab `slab` (the last may be thinner).
  std::uint32_t slab_first(std::uint32_t slab) const;
  std::uint32_t slab_size(std::uint32_t slab) const;

  // Builds slab `slab` from its samples (slab_size(slab) slices, [z][y][x])
  // and, optionally, its keep mask (the same shape), as add_slab would. Uses
  // options.build.threads threads (0: every core).
  BuiltSlab build(std::uint32_t slab, const float* samples, const std::uint8_t* keep = nullptr) const;
  BuiltSlab build(std::uint32_t slab, const std::uint16_t* samples, const std::uint8_t* keep = nullptr) const;

 private:
  template <typename Source>
  BuiltSlab build_any(std::uint32_t slab, const Source* samples, const std::uint8_t* keep) const;

  Dims dims_;
  StreamingOptions options_;
  std::uint32_t slab_slices_ = 1;
};

}  // namespace ivol
