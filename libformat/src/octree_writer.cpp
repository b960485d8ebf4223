// Writes an in-memory octree level by level from the root down (spec §15):
// the metadata (first in framed files), then the values of level l, then its
// nodes.
#include <chrono>

#include "block_pipeline.hpp"
#include "ivol/error.hpp"
#include "ivol/writer.hpp"

namespace ivol {

WriteStats write_octree(const Octree& octree, const Metadata& metadata, const std::string& path,
                        const WriteOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (options.block_bytes < 8 || options.block_bytes > (64u << 20))
    throw Error(ErrorClass::InvalidArgument, "write: block size must be 8 B .. 64 MiB");
  const VolumeLayout& layout = octree.layout();
  FileWriter writer(path, layout, options.framed_blocks);
  if (writer.framed()) writer.write_metadata(metadata);  // first, so that a cut file keeps it (spec §15)
  detail::BlockPipeline pipeline(writer, options);
  const std::size_t width = encoding_width(layout.encoding);
  const auto* values = octree.value_bytes().data();
  const auto* nodes = reinterpret_cast<const std::uint8_t*>(octree.nodes().data());
  for (unsigned l = 0; l <= layout.depth; ++l) {
    detail::BlockAssembler value_blocks(pipeline, Stream::Values, l, layout.first_value(l), width, options.block_bytes);
    value_blocks.append(values + layout.first_value(l) * width, layout.level_values(l));
    value_blocks.finish();
    detail::BlockAssembler node_blocks(pipeline, Stream::Nodes, l, layout.first_inner(l), 8, options.block_bytes);
    node_blocks.append(nodes + layout.first_inner(l) * 8, layout.inner_count[l]);
    node_blocks.finish();
  }
  pipeline.flush();
  writer.finish(metadata, layout.inner_count);
  WriteStats stats;
  stats.file_bytes = writer.bytes_written();
  stats.block_count = writer.block_count();
  stats.decoded_bytes = pipeline.decoded_bytes();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace ivol
