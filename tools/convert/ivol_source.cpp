#include "ivol_source.hpp"

#include <algorithm>
#include <cstring>

#include "ivol/error.hpp"
#include "ivol/reader.hpp"
#include "ivol_io.hpp"
#include "sizes.hpp"

namespace ivol::convert {
namespace {

class IvolStoredSlabReader final : public SlabReader {
 public:
  IvolStoredSlabReader(const std::string& path, std::uint64_t memory_bytes)
      : reader_(path, [&] {
          ReaderOptions options;
          options.cache_bytes = export_cache_bytes(memory_bytes);
          return options;
        }()) {
    const Dims& dims = reader_.layout().dims;
    const Box all{{0, 0, 0}, {dims[0], dims[1], dims[2]}};
    shape_ = export_shape(reader_, all, 0, stored_sample_type(reader_.layout().encoding));
    // export_shape names the geometry's origin for an export; here it is
    // where the output's geometry comes from.
    shape_.voxel_size_from = shape_.origin_from = shape_.unit_from = shape_.quantity_from = "the input's metadata";
  }

  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    const Dims& dims = reader_.layout().dims;
    reader_.read_box_bits_into(Box{{0, 0, z0}, {dims[0], dims[1], z0 + count}}, out);
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

  const Reader& reader() const { return reader_; }

 private:
  Reader reader_;
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

std::unique_ptr<SlabReader> open_ivol_stored_slabs(const std::string& path, std::uint64_t memory_bytes,
                                                   IvolSourceInfo* info) {
  auto source = std::make_unique<IvolStoredSlabReader>(path, memory_bytes);
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

void inherit_structure(nlohmann::json& structure, const nlohmann::json& input_structure) {
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
