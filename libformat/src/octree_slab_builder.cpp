// OctreeSlabBuilder: one slab's subtrees built as the streaming writer builds
// them (slab_subtrees.hpp), laid out as bytes.
#include "ivol/octree_slab_builder.hpp"

#include <cstring>
#include <mutex>
#include <string>

#include "slab_subtrees.hpp"

namespace ivol {

using detail::BuildStats;
using detail::BuiltSlabHeader;
using detail::BuiltSubtreeRecord;
using detail::LevelArrays;
using detail::SlabGrid;
using detail::SubtreeRecord;

OctreeSlabBuilder::OctreeSlabBuilder(const Dims& dims, const StreamingOptions& options)
    : dims_(dims), options_(options) {
  detail::check_streaming_options(dims, options);
  slab_slices_ = detail::choose_slab_slices(dims, options);
}

std::uint32_t OctreeSlabBuilder::slab_slices() const { return slab_slices_; }
std::uint32_t OctreeSlabBuilder::slab_count() const { return SlabGrid(dims_, slab_slices_).slab_count(); }
std::uint32_t OctreeSlabBuilder::slab_first(std::uint32_t slab) const { return slab * slab_slices_; }
std::uint32_t OctreeSlabBuilder::slab_size(std::uint32_t slab) const {
  return SlabGrid(dims_, slab_slices_).slices(slab);
}

BuiltSlab OctreeSlabBuilder::build(std::uint32_t slab, const float* samples, const std::uint8_t* keep) const {
  return build_any(slab, samples, keep);
}

BuiltSlab OctreeSlabBuilder::build(std::uint32_t slab, const std::uint16_t* samples, const std::uint8_t* keep) const {
  return build_any(slab, samples, keep);
}

namespace {

template <typename Source, typename Stored>
BuiltSlab build_typed(const Dims& dims, const StreamingOptions& options, std::uint32_t slab_slices, std::uint32_t slab,
                      const Source* samples, const std::uint8_t* keep) {
  const SlabGrid grid(dims, slab_slices);
  if (slab >= grid.slab_count())
    throw Error(ErrorClass::InvalidArgument, "OctreeSlabBuilder: slab " + std::to_string(slab) + " of a volume of " +
                                                 std::to_string(grid.slab_count()) + " slabs");
  detail::Builder<Source, Stored> builder(nullptr, dims, options.build, nullptr);
  const std::uint32_t count = grid.subtrees_per_slab();
  std::vector<BuiltSubtreeRecord> records(count);
  std::vector<std::uint64_t> counts(std::size_t{count} * grid.levels * 2);
  std::vector<std::uint8_t> data;
  std::mutex data_mutex;
  const unsigned threads =
      std::max(1u, options.build.threads ? options.build.threads : std::thread::hardware_concurrency());
  const BuildStats stats = detail::build_slab_subtrees<Source, Stored>(
      builder, grid, slab, samples, keep, threads,
      [&](std::uint32_t n, const SubtreeRecord& record, const LevelArrays<Stored>& arrays) {
        std::lock_guard<std::mutex> lock(data_mutex);
        records[n] = detail::to_wire(record, data.size());
        for (unsigned l = grid.subtree_level; l <= grid.depth; ++l) {
          const auto& nodes = arrays.nodes[l];
          const auto& values = arrays.values[l];
          const auto* node_bytes = reinterpret_cast<const std::uint8_t*>(nodes.data());
          const auto* value_bytes = reinterpret_cast<const std::uint8_t*>(values.data());
          data.insert(data.end(), node_bytes, node_bytes + nodes.size() * 8);
          data.insert(data.end(), value_bytes, value_bytes + values.size() * sizeof(Stored));
          counts[(std::size_t{n} * grid.levels + (l - grid.subtree_level)) * 2] = nodes.size();
          counts[(std::size_t{n} * grid.levels + (l - grid.subtree_level)) * 2 + 1] = values.size();
        }
      });

  BuiltSlabHeader header{};
  std::memcpy(header.magic, "ivolslab", 8);
  header.version = detail::kBuiltSlabVersion;
  header.slab = slab;
  for (int a = 0; a < 3; ++a) header.dims[a] = dims[a];
  header.slab_slices = slab_slices;
  header.encoding = static_cast<std::uint8_t>(options.build.encoding);
  header.source_is_float = std::is_same_v<Source, float> ? 1 : 0;
  header.with_keep = keep != nullptr ? 1 : 0;
  header.coarsened = stats.coarsened ? 1 : 0;
  header.value_scale = options.build.value_scale;
  header.value_offset = options.build.value_offset;
  header.max_abs_error = stats.max_abs_error;
  header.kept = stats.kept;
  header.subtree_count = count;
  header.data_bytes = data.size();

  BuiltSlab built;
  auto& out = built.bytes;
  out.reserve(sizeof header + records.size() * sizeof(BuiltSubtreeRecord) + counts.size() * 8 + data.size());
  const auto append = [&out](const void* p, std::size_t size) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    out.insert(out.end(), b, b + size);
  };
  append(&header, sizeof header);
  append(records.data(), records.size() * sizeof(BuiltSubtreeRecord));
  append(counts.data(), counts.size() * 8);
  append(data.data(), data.size());
  return built;
}

}  // namespace

template <typename Source>
BuiltSlab OctreeSlabBuilder::build_any(std::uint32_t slab, const Source* samples, const std::uint8_t* keep) const {
  if (options_.build.encoding == ValueEncoding::Float32)
    return build_typed<Source, std::uint32_t>(dims_, options_, slab_slices_, slab, samples, keep);
  return build_typed<Source, std::uint16_t>(dims_, options_, slab_slices_, slab, samples, keep);
}

}  // namespace ivol
