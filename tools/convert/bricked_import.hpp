// The bricked regular grid (spec §8A.4) as an import's structure: whether an
// import gets one (StructureChoice::Auto's rule), what a layer of its bricks
// holds in memory, samples turned into the stored values (16-bit, or
// float32's bits), and the writer's side. import_to_ivol uses all of it in one process; a distributed
// dense reconstruction (recon_built_layers.hpp) turns each rank's slabs into
// stored values there and adds them in z order on rank 0, so that both write
// the same file.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ivol/bricked_writer.hpp"
#include "ivol_io.hpp"

namespace ivol::convert {

struct BrickedKeepOutcome;  // bricked_keep.hpp

// What a layer of bricks of `shape` holds when its samples are read `slices`
// slices at a time (a part of a layer, or whole layers): the layers' 16-bit
// values, one layer's encoded bricks (counted at their worst, as large as
// the values), the samples read (and their float32 copy, for types other
// than float32 that binary16 rounds), and the stored levels' sums and
// bricks. Saturates instead of overflowing.
std::uint64_t bricked_layer_bytes(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                                  std::uint32_t slices);
// What a layer may hold: options.layer_budget_bytes, else all of --memory.
std::uint64_t bricked_layer_budget(const ImportOptions& options);
// The slices read at once within the budget: whole layers, as many as fit
// (powers of two of them, up to the volume) where thicker reads pay
// (SlabReader::thick_reads_pay), else one layer; a layer's slices halved
// until they fit when it does not; 0 when not even one slice fits.
std::uint32_t bricked_read_slices(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                                  bool thick_reads_pay = true);

// StructureChoice::Auto's rule (or the flag): whether `shape` becomes a
// bricked grid. Sets report.structure and, for Auto, report.structure_reason
// (why, either way). Throws InvalidArgument when --structure bricked cannot be.
bool choose_bricked(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                    ImportReport& report);

// Whether the samples' bytes are the values `build` stores, as they are
// (binary16 samples kept as binary16, float32 as float32, uint16 codes with
// no offset): a slab is then read into the stored values themselves, not
// copied there (a hundredth of a binary16 conversion's time).
bool stored_as_read(const DenseVolume& shape, const BuildOptions& build);

// `count` samples of shape.type as the 16-bit values `build` stores: every
// bit of binary16 samples, integer samples as codes, other values rounded to
// binary16 with what changes counted into `loss`. `scratch` holds float32
// copies where the samples are not float32.
void samples_to_stored(const DenseVolume& shape, const BuildOptions& build, const std::uint8_t* samples,
                       std::uint64_t count, std::vector<float>& scratch, std::uint16_t* stored, LossTally& loss);
// The same for a float32 grid: the samples as float32 bits, every bit of
// float32 samples as it is (every other sample type is a float32 exactly).
void samples_to_stored(const DenseVolume& shape, const BuildOptions& build, const std::uint8_t* samples,
                       std::uint64_t count, std::vector<float>& scratch, std::uint32_t* stored, LossTally& loss);

// The type a grid's stored values are handled in: std::uint16_t, or
// std::uint32_t for float32; calls `f` with a value of it.
template <class F>
decltype(auto) with_stored_type(ValueEncoding encoding, F&& f) {
  if (encoding == ValueEncoding::Float32) return f(std::uint32_t{});
  return f(std::uint16_t{});
}

// The writer's side: layers of stored values in z order, then finish().
// Threads the writer encodes bricks on: one, and as many more as the
// budget holds beside the layers read (bricked_layer_bytes counts one).
unsigned encoder_threads(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding);
// Whether the budget also holds a second layer's samples and stored values
// (read `read` slices at a time), beside the layer and the encoder threads'
// bricks: the next layer is then read while one is encoded.
bool bricked_prefetch(const DenseVolume& shape, const ImportOptions& options, ValueEncoding encoding,
                      std::uint32_t read);

class BrickedImport {
 public:
  BrickedImport(const DenseVolume& shape, const std::string& path, const ImportOptions& options,
                const StreamingOptions& streaming);
  std::uint32_t layer_slices() const { return layer_slices_; }
  std::uint32_t next_layer_first() const { return writer_.next_layer_first(); }
  std::uint32_t next_layer_count() const { return writer_.next_layer_count(); }
  void add_layer(const std::uint16_t* stored) { writer_.add_layer(stored); }
  void add_layer(const std::uint32_t* stored) { writer_.add_layer(stored); }
  // After the last layer: refuses `loss` unless options.allow_lossy, then
  // writes the metadata (geometry, the choice and its reason, the outcome,
  // and what a keep rule did, where one was applied) and the file; fills
  // report's outcome.
  void finish(const LossTally& loss, ImportReport& report, const BrickedKeepOutcome* keep = nullptr);

 private:
  const DenseVolume& shape_;
  const ImportOptions& options_;
  std::string path_;
  ValueEncoding encoding_;
  std::uint32_t layer_slices_;
  BrickedGridWriter writer_;
};

}  // namespace ivol::convert
