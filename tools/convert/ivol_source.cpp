#include "ivol_source.hpp"

#include <algorithm>
#include <cstring>

#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol_io.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

class IvolStoredSlabReader final : public IvolStoredSlabs {
 public:
  IvolStoredSlabReader(const std::string& path, std::uint64_t memory_bytes, bool salvage)
      : reader_(path,
                [&] {
                  ReaderOptions options;
                  options.cache_bytes = export_cache_bytes(memory_bytes);
                  options.salvage = salvage;
                  return options;
                }()),
        salvage_(salvage) {
    const Dims& dims = reader_.layout().dims;
    const Box all{{0, 0, 0}, {dims[0], dims[1], dims[2]}};
    shape_ = export_shape(reader_, all, 0, stored_sample_type(reader_.layout().encoding));
    // export_shape names the geometry's origin for an export; here it is
    // where the output's geometry comes from.
    shape_.voxel_size_from = shape_.origin_from = shape_.unit_from = shape_.quantity_from = "the input's metadata";
    if (!reader_.metadata_problem().empty()) {
      shape_.quantity.clear();  // the defaults', not the input's
      shape_.quantity_from.clear();
    }
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const Dims& dims = reader_.layout().dims;
    std::vector<DamagedRegion> damaged;
    reader_.read_box_bits_into(Box{{0, 0, z0}, {dims[0], dims[1], z0 + count}}, out, 0, salvage_ ? &damaged : nullptr);
    damaged_count_ += damaged.size();
    for (DamagedRegion& d : damaged)
      if (damaged_.size() < kMaxListed) damaged_.push_back(std::move(d));
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    // read_box_bits gives little-endian bits; samples are native.
    const std::size_t width = sample_size(shape_.type);
    auto* bytes = static_cast<std::uint8_t*>(out);
    const std::uint64_t n = std::uint64_t{dims[0]} * dims[1] * count;
    for (std::uint64_t i = 0; i < n; ++i) std::reverse(bytes + i * width, bytes + (i + 1) * width);
#endif
  }

  // A read of many slices decodes each block it meets once; thin reads of
  // an octree's Morton-ordered blocks would decode them again and again.
  bool thick_reads_pay() const override { return true; }

  const std::vector<DamagedRegion>& damaged() const override { return damaged_; }
  std::uint64_t damaged_count() const override { return damaged_count_; }
  const SalvageInfo* salvage() const override { return reader_.info().salvage.get(); }
  const VolumeLayout& layout() const override { return reader_.layout(); }
  const std::string& metadata_problem() const override { return reader_.metadata_problem(); }

  const Reader& reader() const { return reader_; }

 private:
  Reader reader_;
  bool salvage_;
  std::vector<DamagedRegion> damaged_;
  std::uint64_t damaged_count_ = 0;
};

}  // namespace

SampleType stored_sample_type(ValueEncoding encoding) {
  switch (encoding) {
    case ValueEncoding::Binary16:
      return SampleType::Float16;
    case ValueEncoding::UInt16:
      return SampleType::UInt16;
    case ValueEncoding::Float32:
      break;
  }
  return SampleType::Float32;
}

std::unique_ptr<IvolStoredSlabs> open_ivol_stored_slabs(const std::string& path, std::uint64_t memory_bytes,
                                                        IvolSourceInfo* info, bool salvage) {
  auto source = std::make_unique<IvolStoredSlabReader>(path, memory_bytes, salvage);
  if (info) {
    const Reader& reader = source->reader();
    const VolumeLayout& layout = reader.layout();
    info->kind = layout.kind;
    info->file_bytes = reader.info().file_size;
    info->encoding = layout.encoding;
    info->value_scale = layout.value_scale;
    info->value_offset = layout.value_offset;
    info->metadata = reader.metadata();
    // The grids of spec §8A hold every voxel; the others may hold coarse
    // cells, of a keep rule (convert --keep, recon --keep) or of a
    // reconstruction into a structure (recon --structure).
    const nlohmann::json& structure = info->metadata.structure;
    const nlohmann::json& provenance = info->metadata.provenance;
    const auto lossless = structure.find("lossless");
    const auto recon = provenance.find("reconstruction");
    const bool reconstructed_coarse =
        recon != provenance.end() && recon->is_object() && (recon->contains("structure") || recon->contains("keep"));
    info->coarse_leaves = layout.kind != StructureKind::Bricked &&
                          ((lossless != structure.end() && lossless->is_boolean() && !lossless->get<bool>()) ||
                           structure.contains("keep") || reconstructed_coarse);
  }
  return source;
}

nlohmann::json salvage_record(const IvolStoredSlabs& source) {
  nlohmann::json record = nlohmann::json::object();
  if (source.salvage()) {
    record["index"] = source.salvage()->reason;
    record["metadata"] = source.salvage()->metadata;
  }
  if (!source.metadata_problem().empty()) record["metadata"] = "unreadable: " + source.metadata_problem();
  record["regions_filled"] = source.damaged_count();
  nlohmann::json regions = nlohmann::json::array();
  for (std::size_t n = 0; n < source.damaged().size() && n < 100; ++n) {
    const DamagedRegion& d = source.damaged()[n];
    regions.push_back(
        {{"box", {d.region.lo[0], d.region.lo[1], d.region.lo[2], d.region.hi[0], d.region.hi[1], d.region.hi[2]}},
         {"level", d.level},
         {"damage", d.message}});
  }
  record["regions"] = std::move(regions);
  record["filled_from"] = "the nearest readable coarser level (octree), else stored code 0 (grids of spec 8A)";
  return record;
}

void set_reencoding(ImportOptions& options, const IvolSourceInfo& input) {
  options.stored_values = ImportOptions::StoredValues{input.value_scale, input.value_offset};
  options.input_structure = input.metadata.structure;
  options.input_coarse_leaves = input.coarse_leaves;
  options.metadata.user = input.metadata.user;
  options.metadata.other = input.metadata.other;
  options.metadata.quantity = input.metadata.quantity;
  options.metadata.value_unit = input.metadata.value_unit;
  // The CLI's provenance (provenance_after_conversion) already holds it.
  nlohmann::json& provenance = options.metadata.provenance;
  if (!provenance.is_object()) provenance = nlohmann::json::object();
  if (!provenance.contains("derived_from") && !input.metadata.provenance.empty())
    provenance["derived_from"] = input.metadata.provenance;
}

void inherit_structure(Metadata& metadata, const nlohmann::json& input_structure) {
  nlohmann::json& structure = metadata.structure;
  if (metadata.provenance.is_object() && metadata.provenance.contains("salvage")) structure["lossless"] = false;
  if (!input_structure.is_object()) return;
  const auto source_encoding = input_structure.find("source_encoding");
  if (source_encoding != input_structure.end() && source_encoding->is_string())
    structure["source_encoding"] = *source_encoding;
  const auto keep = input_structure.find("keep");
  if (keep != input_structure.end() && !structure.contains("keep")) structure["keep"] = *keep;
  const auto lossless = input_structure.find("lossless");
  if (lossless != input_structure.end() && lossless->is_boolean() && !lossless->get<bool>()) {
    structure["lossless"] = false;
    const auto error = input_structure.find("max_abs_error");
    if (error != input_structure.end() && error->is_number()) {
      const double own = structure.value("max_abs_error", 0.0);
      structure["max_abs_error"] = std::max(own, error->get<double>());
    }
  }
}

}  // namespace ivol::convert
