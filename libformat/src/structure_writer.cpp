// Any structure into an .ivol file of its kind, part by part as its values
// become final.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "block_pipeline.hpp"
#include "ivol/error.hpp"
#include "ivol/structure_stream.hpp"

namespace ivol {

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The grids' values in file order (spec §8A): the bricks' order for the
// regular and nested grids, (k, j, i) over the intervals for the rectilinear
// grid. Knows each value's brick and first slice.
class FileOrder {
 public:
  explicit FileOrder(const VoxelStructure& s) : s_(s), rectilinear_(s.kind() == StructureKind::Rectilinear) {
    const auto& bricks = s.bricks();
    later_origin_.assign(bricks.size() + 1, UINT32_MAX);
    for (std::size_t n = bricks.size(); n-- > 0;)
      later_origin_[n] = std::min(later_origin_[n + 1], bricks[n].origin[2]);
    if (rectilinear_) {
      rx_ = runs(0);
      ry_ = runs(1);
      // Each interval's run (a brick's index along the axis) and place in it.
      for (int a = 0; a < 3; ++a) {
        intervals_[a] = s.borders()[a].size() - 1;
        std::uint32_t run = 0, place = 0;
        for (std::size_t i = 0; i < intervals_[a]; ++i) {
          run_of_[a].push_back(run);
          place_in_run_[a].push_back(place);
          const Brick& first_of_run = bricks[a == 0 ? run : a == 1 ? run * rx_ : run * rx_ * ry_];
          if (++place == first_of_run.count[a]) ++run, place = 0;
        }
      }
    }
    settle();
  }
  bool done() const { return done_; }
  std::uint32_t brick() const { return brick_; }
  std::uint64_t value() const { return value_; }
  std::uint32_t z_start() const { return z_start_; }
  // The first slice of any value not yet passed: everything ending at or
  // below it has been passed.
  std::uint32_t passed_below() const {
    if (done_) return s_.dims()[2];
    return rectilinear_ ? z_start_ : std::min(z_start_, later_origin_[brick_ + 1]);
  }
  void next() {
    ++n_;
    settle();
  }

 private:
  // Bricks are the cross product of runs along each axis, x fastest: the runs
  // along x are the bricks of the first row, along y the rows of the first layer.
  std::uint32_t runs(int a) const {
    const auto& bricks = s_.bricks();
    std::uint32_t count = 0;
    if (a == 0) {
      while (count < bricks.size() && bricks[count].origin[1] == bricks[0].origin[1] &&
             bricks[count].origin[2] == bricks[0].origin[2])
        ++count;
    } else {
      const std::uint32_t rx = runs(0);
      while (count * rx < bricks.size() && bricks[count * rx].origin[2] == bricks[0].origin[2]) ++count;
    }
    return count;
  }
  void settle() {
    const auto& bricks = s_.bricks();
    if (rectilinear_) {
      const std::uint64_t nx = intervals_[0], ny = intervals_[1];
      if (n_ >= nx * ny * intervals_[2]) {
        done_ = true;
        return;
      }
      const std::uint64_t i = n_ % nx, j = (n_ / nx) % ny, k = n_ / (nx * ny);
      brick_ = (run_of_[2][k] * ry_ + run_of_[1][j]) * rx_ + run_of_[0][i];
      const Brick& b = bricks[brick_];
      value_ = b.first_value + (std::uint64_t{place_in_run_[2][k]} * b.count[1] + place_in_run_[1][j]) * b.count[0] +
               place_in_run_[0][i];
      z_start_ = s_.borders()[2][k];
      return;
    }
    // Bricks are unpacked from their records once each, not once a value.
    for (;; ++brick_) {
      if (brick_ >= bricks.size()) {
        done_ = true;
        return;
      }
      if (unpacked_ != brick_) current_ = bricks[brick_], unpacked_ = brick_;
      if (n_ < current_.first_value + current_.voxel_count()) break;
    }
    const Brick& b = current_;
    value_ = n_;
    const std::uint64_t k = (n_ - b.first_value) / (std::uint64_t{b.count[0]} * b.count[1]);
    z_start_ = static_cast<std::uint32_t>(b.origin[2] + k * b.voxel[2]);
  }

  const VoxelStructure& s_;
  bool rectilinear_;
  std::vector<std::uint32_t> later_origin_;  // the lowest first slice of bricks n.. onwards
  std::array<std::uint64_t, 3> intervals_{};
  std::array<std::vector<std::uint32_t>, 3> run_of_, place_in_run_;
  std::uint64_t rx_ = 0, ry_ = 0;
  std::uint64_t n_ = 0;
  std::uint32_t brick_ = 0;
  Brick current_;  // brick unpacked_, unpacked
  std::uint32_t unpacked_ = UINT32_MAX;
  std::uint64_t value_ = 0;
  std::uint32_t z_start_ = 0;
  bool done_ = false;
};

}  // namespace

struct StructureStreamWriter::Impl {
  const VoxelStructure& structure;
  StreamingOptions options;
  double busy_seconds = 0;  // in this writer's calls, not between them
  StreamingResult result;

  // The octree: slabs of full-resolution samples into StreamingOctreeWriter.
  std::unique_ptr<StreamingOctreeWriter> octree;
  std::vector<float> slab;
  std::vector<std::uint8_t> keep;
  std::unique_ptr<OctreeSlabFiller> filler;

  // The grids: borders or cell words at once, then the values in file order.
  VolumeLayout layout;
  std::unique_ptr<FileWriter> file;
  std::unique_ptr<detail::BlockPipeline> pipeline;
  std::unique_ptr<detail::BlockAssembler> values_out;
  std::unique_ptr<FileOrder> order;

  Impl(const VoxelStructure& s, const std::string& path, const StreamingOptions& o, const Metadata* metadata)
      : structure(s), options(o) {
    if (s.kind() == StructureKind::Octree)
      open_octree(path);
    else
      open_grid(path, metadata);
  }

  void open_octree(const std::string& path) {
    const Dims& dims = structure.dims();
    octree = std::make_unique<StreamingOctreeWriter>(path, dims, options);
    slab.resize(std::uint64_t{octree->slab_slices()} * dims[0] * dims[1]);
    keep.resize(slab.size());
    filler = std::make_unique<OctreeSlabFiller>(structure);
  }

  // Full resolution exactly where the octree has fine voxels; each coarse
  // voxel one leaf.
  void write_octree_slab(StructureValueSource& values) {
    const std::uint32_t z0 = octree->next_slab_first();
    const std::uint32_t z1 = z0 + octree->next_slab_count();
    filler->fill(z0, z1, values, slab.data(), keep.data());
    octree->add_slab(slab.data(), keep.data());
    values.release_below(z1);
  }

  void open_grid(const std::string& path, const Metadata* metadata) {
    const BuildOptions& build = options.build;
    layout.kind = structure.kind();
    layout.dims = structure.dims();
    layout.depth = depth_for(layout.dims);
    layout.encoding = build.encoding;
    layout.value_scale = build.value_scale;
    layout.value_offset = build.value_offset;
    layout.inner_count.assign(layout.depth + 1, 0);
    unsigned cell_log2 = 0;
    while ((1u << cell_log2) < structure.nested_cell()) ++cell_log2;
    layout.cell_log2 = static_cast<std::uint8_t>(layout.kind == StructureKind::Nested ? cell_log2 : 0);

    file = std::make_unique<FileWriter>(path, layout, options.write.framed_blocks);
    if (metadata && file->framed()) file->write_metadata(*metadata);
    pipeline = std::make_unique<detail::BlockPipeline>(*file, options.write);
    const std::uint32_t block = options.write.block_bytes;
    if (layout.kind == StructureKind::Rectilinear) {
      detail::BlockAssembler borders(*pipeline, Stream::Borders, 0, 0, 4, block);
      for (const auto& list : structure.borders()) borders.append(list.data(), list.size());
      borders.finish();
    }
    if (layout.kind == StructureKind::Nested) {
      detail::BlockAssembler cells(*pipeline, Stream::Cells, 0, 0, 8, block);
      for (const Brick& b : structure.bricks()) {
        const bool fine = b.voxel == std::array<std::uint32_t, 3>{1, 1, 1};
        const std::uint64_t word = make_node_word(static_cast<std::uint8_t>(fine ? cell_log2 : 0), b.first_value);
        cells.append(&word, 1);
      }
      cells.finish();
    }
    values_out = std::make_unique<detail::BlockAssembler>(*pipeline, Stream::Values, 0, 0,
                                                          encoding_width(build.encoding), block);
    order = std::make_unique<FileOrder>(structure);
  }

  void write_grid_values(std::uint32_t z_complete, StructureValueSource& values) {
    const BuildOptions& build = options.build;
    const bool identity = build.value_scale == 1.0 && build.value_offset == 0.0;
    for (; !order->done() && order->z_start() < z_complete; order->next()) {
      const float v = values.value(order->brick(), order->value());
      const double stored = identity ? v : (v - build.value_offset) / build.value_scale;
      const std::uint32_t bits = encode_value(build.encoding, stored);
      const double err = std::fabs(layout.physical(decode_value(build.encoding, bits)) - v);
      result.max_abs_error = std::max(result.max_abs_error, err);
      values_out->append(&bits, 1);  // little-endian: the low bytes are the value
    }
    values.release_below(order->passed_below());
  }

  void write_ready(std::uint32_t z_complete, StructureValueSource& values) {
    const auto started = std::chrono::steady_clock::now();
    if (octree) {
      while (octree->next_slab_count() > 0 && octree->next_slab_first() + octree->next_slab_count() <= z_complete)
        write_octree_slab(values);
    } else {
      write_grid_values(z_complete, values);
    }
    busy_seconds += seconds_since(started);
  }

  StreamingResult finish(const Metadata& metadata, StructureValueSource& values) {
    const std::uint32_t all = structure.dims()[2];
    write_ready(all, values);
    const auto started = std::chrono::steady_clock::now();
    if (octree) {
      StreamingResult outcome = octree->finish(metadata);
      outcome.write.seconds = busy_seconds + seconds_since(started);
      return outcome;
    }
    values_out->finish();
    pipeline->flush();
    file->finish(metadata, layout.inner_count);
    result.lossless = result.max_abs_error == 0.0;
    result.kept_voxels = structure.voxel_count();
    result.write.file_bytes = file->bytes_written();
    result.write.block_count = file->block_count();
    result.write.decoded_bytes = pipeline->decoded_bytes();
    result.write.seconds = busy_seconds + seconds_since(started);
    return result;
  }
};

StructureStreamWriter::StructureStreamWriter(const VoxelStructure& structure, const std::string& path,
                                             const StreamingOptions& options)
    : impl_(std::make_unique<Impl>(structure, path, options, nullptr)) {}

StructureStreamWriter::StructureStreamWriter(const VoxelStructure& structure, const std::string& path,
                                             const StreamingOptions& options, const Metadata& metadata)
    : impl_(std::make_unique<Impl>(structure, path, options, &metadata)) {}

StructureStreamWriter::~StructureStreamWriter() = default;

void StructureStreamWriter::write_ready(std::uint32_t z_complete, StructureValueSource& values) {
  impl_->write_ready(z_complete, values);
}

std::uint32_t StructureStreamWriter::slab_slices() const { return impl_->octree ? impl_->octree->slab_slices() : 1; }

std::uint64_t StructureStreamWriter::index_bytes() const { return impl_->octree ? impl_->octree->index_bytes() : 0; }

StreamingResult StructureStreamWriter::finish(const Metadata& metadata, StructureValueSource& values) {
  return impl_->finish(metadata, values);
}

StreamingResult write_structure(const VoxelStructure& structure, const std::string& path, const Metadata& metadata,
                                StreamingOptions options) {
  WholeStructureValues values(structure);
  StructureStreamWriter writer(structure, path, options, metadata);
  return writer.finish(metadata, values);
}

}  // namespace ivol
