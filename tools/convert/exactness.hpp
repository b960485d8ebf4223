// The exactness contract of ivol's conversions: every conversion either keeps
// the values exactly (bit for bit on the stored values, or value for value
// where the target type holds every value) or is refused, naming the loss and
// --allow-lossy, the option that accepts it. The loss is counted voxel by
// voxel while the conversion streams; the refusal comes before the output is
// renamed into place, so nothing is left behind.
#pragma once

#include <cstdint>
#include <string>

#include "dense_volume.hpp"
#include "ivol/encoding.hpp"
#include "ivol/geometry.hpp"

namespace ivol::convert {

// What a conversion changed, counted while it runs.
struct LossTally {
  std::uint64_t voxels = 0;            // voxels whose value or bits changed
  double max_error = 0.0;              // largest |new - old| (infinity for a value that became infinite)
  std::uint64_t out_of_range = 0;      // of them: values the target's range does not hold (clamped or infinite)
  double lowest = 0.0, highest = 0.0;  // the range of those values
  std::uint64_t nans = 0;              // NaNs an integer type cannot hold (written as 0)
  std::uint64_t nan_payloads = 0;      // NaNs whose sign or payload changed
  std::uint64_t signed_zeros = 0;      // −0 that became +0

  bool exact() const { return voxels == 0; }
  void merge(const LossTally& other);
  // One changed voxel: `from` the value it had, `to` the value it gets.
  void add(double from, double to);
  void add_out_of_range(double from, double to);
};

// "12 of 4096 voxels change (largest error 0.5; 3 values in [-2, 300] outside
// u8's range 0..255; 2 NaN that an integer cannot hold)".
std::string describe_loss(const LossTally& loss, std::uint64_t total, const std::string& target);

// Throws ivol::Error(InvalidArgument) when `loss` is not exact: `what` names
// the conversion ("a.ivol -> b.raw as u8"), `target` what does not hold the
// values ("u8"), `hint` an exact alternative when there is one ("--out-type
// f32"); the message ends with --allow-lossy.
void refuse_loss(const LossTally& loss, std::uint64_t total, const std::string& what, const std::string& target,
                 const std::string& hint = "");

// Converts stored values of an .ivol file (encoding_width() bytes each,
// little-endian, the file's encoding, scale and offset) into samples of
// `type`, counting what changes. Bit for bit where the file's stored type is
// the target's (binary16 -> f16, float32 -> f32, uint16 codes -> u16 with
// scale 1 and offset 0); otherwise through the physical value in binary64,
// exact where the target holds it. Integers round to nearest and clamp.
void stored_to_samples(const VolumeLayout& layout, const std::uint8_t* stored, std::uint64_t count, SampleType type,
                       std::uint8_t* out, LossTally& loss);

// True when stored_to_samples into `type` cannot change a value, whatever
// the file holds (binary16 -> f16 or f32, float32 -> f32, uint16 codes with
// scale 1 -> u16 or f32 with offset 0, i16 or f32 with offset -32768).
bool always_exact(const VolumeLayout& layout, SampleType type);

// Counts the float32 values (exact conversions of the source's samples) that
// `encoding` (scale 1, offset 0) does not hold bit for bit.
void tally_encoding(ValueEncoding encoding, const float* values, std::uint64_t count, LossTally& loss);

// The range of a sample type as text ("0..255"; floats: "finite binary16").
std::string sample_range(SampleType type);

}  // namespace ivol::convert
