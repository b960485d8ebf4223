// Writing a bricked regular grid (spec §8A.4, structure_kind 5, format 1.3):
// every voxel kept, in bricks of 2^b voxels per side, one brick per values
// block, each brick of 16-bit values predicted (codec 3), each brick of
// float32 values as its byte planes (codec 2). What a lossless every-voxel
// volume becomes: an octree of one-voxel leaves stores averages and node
// words besides the same values, and its Morton-order blocks cannot be
// predicted in 3-D.
//
// The volume arrives as layers of 2^b slices (z increasing); memory holds one
// layer of values and its encoded bricks, and for each stored level of
// detail k a slice of binary64 sums and a layer of its bricks
// ((size_x · size_y / 4^k) · (8 + 4 · 2^b) bytes: 34 MB at 4000² for k = 3
// and bricks of 32).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "ivol/geometry.hpp"
#include "ivol/metadata.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/writer.hpp"

namespace ivol {

struct BrickedOptions {
  unsigned brick_log2 = 5;                         // 32^3 bricks: 64 KiB of 16-bit values each (bench/RESULTS.md)
  ValueEncoding encoding = ValueEncoding::UInt16;  // binary16, uint16 or float32
  double value_scale = 1.0;
  double value_offset = 0.0;
  int zstd_level = 3;     // codecs 2 and 4; codec 3 at residual_zstd_level(zstd_level)
  bool predicted = true;  // false: zstd over byte planes (codec 2), for comparison
  // Codec 3's entropy coder (spec §7.2; PredictedOptions says which each
  // value takes): Auto takes coder 3 at zstd levels up to 3 and coder 2 in
  // bricks under 64³ above; ZstdPlanes only zstd, which decodes about 2.5
  // times as fast (bench/RESULTS.md), and no codec 6 either; Lanes coder 3
  // and no codec 6, for decoding speed.
  PredictedOptions::Entropy entropy = PredictedOptions::Entropy::Auto;
  unsigned threads = 0;  // 0: all hardware threads
  // Levels of detail stored (spec §8A.5): every level from this one to the
  // coarsest (0: none). From 3, 1/448 more values, and a 1/8 preview reads
  // them instead of the whole file (bench/RESULTS.md, issue 20).
  unsigned first_stored_level = 3;
};

// The zstd level of codec 3's residual planes for a writer asked for
// `zstd_level`: 1 up to level 3, the level asked above it. The residuals are
// nearly noise: zstd's fast strategy (level 1) leaves their literals to the
// Huffman tables and is 0.9 % smaller to 0.1 % larger than level 3, at twice
// its speed; levels 5 to 9 are larger than level 1 on binary16
// (bench/RESULTS.md, issue 22, "zstd levels for codec 3's residuals").
constexpr int residual_zstd_level(int zstd_level) { return zstd_level <= 3 ? 1 : zstd_level; }

class BrickedGridWriter {
 public:
  // Throws Error(InvalidArgument) for brick_log2 outside 1 .. 8.
  BrickedGridWriter(const std::string& path, const Dims& dims, const BrickedOptions& options);
  ~BrickedGridWriter();  // an unfinished writer leaves nothing behind
  BrickedGridWriter(const BrickedGridWriter&) = delete;
  BrickedGridWriter& operator=(const BrickedGridWriter&) = delete;

  // Slices z0 .. z0 + count of the next layer (the last may be thinner); 0
  // when all are added.
  std::uint32_t next_layer_first() const;
  std::uint32_t next_layer_count() const;
  // Adds the next layer: next_layer_count() slices of size_y x size_x stored
  // values (the encoding's bits: std::uint16_t for binary16 and uint16,
  // std::uint32_t for float32; InvalidArgument for the other), [z][y][x].
  // What the metadata will hold, as far as the caller knows it before the
  // values (FileWriter::write_early_metadata): before the first layer.
  void write_early_metadata(const Metadata& metadata);
  void add_layer(const std::uint16_t* values);
  void add_layer(const std::uint32_t* values);
  // After the last layer: writes the metadata, the index and the footer.
  WriteStats finish(const Metadata& metadata);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ivol
