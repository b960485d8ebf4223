// An .ivol file as the source of a conversion into .ivol (`ivol convert
// IN.ivol OUT.ivol`): the migration of an archive to another structure,
// codec, brick size or zstd level. Its stored values at full resolution are
// read slab by slab as they are (binary16 or uint16 codes, float32 bits), so
// that the new file holds every voxel bit for bit with the same value
// encoding, scale and offset, whatever it was written from.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/encoding.hpp"
#include "ivol/geometry.hpp"
#include "ivol/metadata.hpp"
#include "ivol/reader.hpp"
#include "ivol_io.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

struct IvolSourceInfo {
  StructureKind kind = StructureKind::Octree;
  std::uint64_t file_bytes = 0;
  ValueEncoding encoding = ValueEncoding::Binary16;
  double value_scale = 1.0;
  double value_offset = 0.0;
  Metadata metadata;  // the input's, whole
  // The input may hold coarse leaves: not a bricked grid, and its metadata
  // names a keep rule, a reconstruction into a structure, or a loss. Its
  // full-resolution voxels then repeat each coarse leaf's value, which an
  // octree keeps as one leaf again (equal leaves merge) and a bricked grid
  // would store voxel by voxel.
  bool coarse_leaves = false;
};

// The sample type the stored values are read as: f16 for binary16, u16 for
// uint16 (the codes, before scale and offset), f32 for float32.
SampleType stored_sample_type(ValueEncoding encoding);

// The reader of an .ivol input's stored values. With `salvage`
// (ReaderOptions::salvage) it reads past damaged blocks and, in format 1.3
// files, past a cut or damaged index: their regions take the nearest
// readable coarser level's value (the grids of spec §8A: stored code 0), and
// damaged() lists them.
class IvolStoredSlabs : public SlabReader {
 public:
  // The regions filled so far, at most kMaxListed of them; damaged_count()
  // counts them all.
  static constexpr std::size_t kMaxListed = 1000;
  virtual const std::vector<DamagedRegion>& damaged() const = 0;
  virtual std::uint64_t damaged_count() const = 0;
  // What the salvaging open found (the index rebuilt from the blocks), or null.
  virtual const SalvageInfo* salvage() const = 0;
  virtual const VolumeLayout& layout() const = 0;
  // Whether the output lacks something of the input: regions filled, or
  // metadata the salvaging open could not read whole.
  bool lost_something() const {
    return damaged_count() > 0 || (salvage() && salvage()->metadata != "complete") || !metadata_problem().empty();
  }
  // Why the input's metadata block could not be read (Reader::metadata_problem).
  virtual const std::string& metadata_problem() const = 0;
};

// Opens `path` with a block cache of export_cache_bytes(memory_bytes). The
// shape carries the input's geometry, quantity, value unit and provenance
// (which the output keeps under provenance.derived_from).
std::unique_ptr<IvolStoredSlabs> open_ivol_stored_slabs(const std::string& path, std::uint64_t memory_bytes,
                                                        IvolSourceInfo* info = nullptr, bool salvage = false);

// provenance.salvage of a file written from a salvaged input: why the input
// was salvaged and how much of its metadata was read, how many regions were
// filled and the first 100 of them (box, level, what was damaged).
nlohmann::json salvage_record(const IvolStoredSlabs& source);

// Sets what an import of that source needs: its stored values kept as they
// are (ImportOptions::stored_values), its structure for inherit_structure,
// whether it may hold coarse leaves; the metadata the new file keeps (its
// quantity and value unit, `user` and unknown keys, and its provenance
// under provenance.derived_from where the options' provenance lacks one).
// Geometry comes from the source's shape.
void set_reencoding(ImportOptions& options, const IvolSourceInfo& input);

// What still holds of the input's structure object in a file re-encoded
// from it, set in the new file's `structure`: the input's source_encoding
// (the new file's source is the input, whose values came from that type),
// its keep rule where the new file records none (its coarse leaves come
// from that rule), and any loss it records (the new file holds the same
// values, so it is as far from the original source: lossless false, the
// larger max_abs_error). A file whose provenance records a salvage
// (salvage_record) is not lossless either.
void inherit_structure(Metadata& metadata, const nlohmann::json& input_structure);

}  // namespace ivol::convert
