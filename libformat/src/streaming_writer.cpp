// StreamingOctreeWriter: subtrees built slab by slab and spilled to disk, the
// levels above them built at the end, the file written level by level.
#include "ivol/streaming_writer.hpp"

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>

#include "block_pipeline.hpp"
#include "ivol/error.hpp"
#include "ivol/octree_slab_builder.hpp"
#include "slab_subtrees.hpp"
#include "spill_file.hpp"
#include "thread_parts.hpp"

namespace ivol {
namespace {

using detail::BuildStats;
using detail::BuiltSlabHeader;
using detail::BuiltSubtreeRecord;
using detail::KeepPyramid;
using detail::LevelArrays;
using detail::NodeResult;
using detail::RegionStats;
using detail::SlabGrid;
using detail::SubtreeRecord;

// Calls work(0 .. count - 1) on `threads` threads; rethrows the first failure.
template <class Work>
void parallel_for(std::uint32_t count, unsigned threads, Work&& work) {
  std::atomic<std::uint32_t> next{0};
  detail::run_parts(std::max(1u, std::min<unsigned>(threads, count)), [&](unsigned) {
    for (std::uint32_t n; (n = next.fetch_add(1)) < count;) work(n);
  });
}

std::string directory_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

}  // namespace

// The part of the writer that does not depend on the sample type.
struct StreamingOctreeWriter::Impl {
  virtual ~Impl() = default;
  virtual void add(const void* samples, const std::uint8_t* keep) = 0;
  virtual void add_built(const BuiltSlab& built) = 0;
  virtual StreamingResult finish(const Metadata& metadata, const StreamingOctreeWriter::AmendMetadata& amend) = 0;
  std::uint32_t slab_slices = 0;
  std::uint32_t slabs_done = 0;
  Dims dims{};
  bool is_float = true;
};

namespace {

template <typename Source, typename Stored>
class Engine final : public StreamingOctreeWriter::Impl {
 public:
  Engine(const std::string& path, const Dims& volume_dims, const StreamingOptions& options, std::uint32_t slab)
      : path_(path),
        options_(options),
        builder_(nullptr, volume_dims, options.build, nullptr),
        slab_grid_(volume_dims, slab),
        spill_(spill_directory_for(path, options.spill_directory)),
        spill_level_(options.spill_zstd_level) {
    dims = volume_dims;
    slab_slices = slab;
    is_float = std::is_same_v<Source, float>;
    depth_ = slab_grid_.depth;
    subtree_level_ = slab_grid_.subtree_level;
    for (int a = 0; a < 3; ++a) grid_[a] = slab_grid_.grid[a];
    const std::uint64_t count = std::uint64_t{grid_[0]} * grid_[1] * grid_[2];
    records_.resize(count);
    levels_ = depth_ - subtree_level_ + 1;
    counts_.assign(count * levels_ * 2, 0);
    stored_.assign(count * levels_ * 2, 0);
    threads_ = std::max(1u, options.build.threads ? options.build.threads : std::thread::hardware_concurrency());
  }

  void add(const void* samples, const std::uint8_t* keep) override {
    const auto start = std::chrono::steady_clock::now();
    const std::uint32_t k = slabs_done;
    begin_slab(k, keep != nullptr);
    const BuildStats slab_stats = detail::build_slab_subtrees<Source, Stored>(
        builder_, slab_grid_, k, static_cast<const Source*>(samples), keep, threads_,
        [&](std::uint32_t n, const SubtreeRecord& record, const LevelArrays<Stored>& arrays) {
          const std::uint64_t index = std::uint64_t{k} * slab_grid_.subtrees_per_slab() + n;
          std::vector<detail::PackedChunk> chunks;
          for (unsigned l = subtree_level_; l <= depth_; ++l) {
            chunks.push_back(detail::pack_chunk(arrays.nodes[l].data(), arrays.nodes[l].size(), 8, spill_level_));
            chunks.push_back(
                detail::pack_chunk(arrays.values[l].data(), arrays.values[l].size(), sizeof(Stored), spill_level_));
          }
          store_subtree(index, record, chunks);
        });
    stats_.merge(slab_stats);
    ++slabs_done;
    build_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  // The same effect as add() with the samples and mask `built` was made
  // from: its subtrees' data go to the spill file as they are.
  void add_built(const BuiltSlab& built) override {
    const auto start = std::chrono::steady_clock::now();
    const std::vector<std::uint8_t>& bytes = built.bytes;
    const std::string what = path_ + ": built slab";
    if (bytes.size() < sizeof(BuiltSlabHeader))
      throw Error(ErrorClass::Malformed,
                  what + ": " + std::to_string(bytes.size()) + " bytes, shorter than its header");
    BuiltSlabHeader header;
    std::memcpy(&header, bytes.data(), sizeof header);
    if (std::memcmp(header.magic, "ivolslab", 8) != 0 || header.version != detail::kBuiltSlabVersion)
      throw Error(ErrorClass::Malformed, what + ": not a built slab of this version");
    const bool same_layout =
        header.dims[0] == dims[0] && header.dims[1] == dims[1] && header.dims[2] == dims[2] &&
        header.slab_slices == slab_slices && header.encoding == static_cast<std::uint8_t>(builder_.layout().encoding) &&
        header.value_scale == builder_.layout().value_scale && header.value_offset == builder_.layout().value_offset &&
        (header.source_is_float != 0) == is_float;
    if (!same_layout)
      throw Error(ErrorClass::InvalidArgument,
                  what + " " + std::to_string(header.slab) + " was made for another layout (" +
                      std::to_string(header.dims[0]) + "x" + std::to_string(header.dims[1]) + "x" +
                      std::to_string(header.dims[2]) + " in slabs of " + std::to_string(header.slab_slices) +
                      "; this writer: " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                      std::to_string(dims[2]) + " in slabs of " + std::to_string(slab_slices) +
                      ", or another encoding, scale, offset or sample type)");
    const std::uint32_t k = slabs_done;
    if (header.slab != k)
      throw Error(ErrorClass::InvalidArgument, what + " " + std::to_string(header.slab) + " given where slab " +
                                                   std::to_string(k) + " is expected (slabs go in z order)");
    const std::uint32_t subtrees = slab_grid_.subtrees_per_slab();
    const std::uint64_t records_at = sizeof header;
    const std::uint64_t counts_at = records_at + std::uint64_t{subtrees} * sizeof(BuiltSubtreeRecord);
    const std::uint64_t data_at = counts_at + std::uint64_t{subtrees} * levels_ * 2 * 8;
    if (header.subtree_count != subtrees || data_at + header.data_bytes != bytes.size())
      throw Error(ErrorClass::Malformed, what + " " + std::to_string(k) + ": " + std::to_string(bytes.size()) +
                                             " bytes do not hold its " + std::to_string(subtrees) + " subtrees");
    begin_slab(k, header.with_keep != 0);
    std::vector<SubtreeRecord> subtree_records(subtrees);
    std::vector<std::uint64_t> data_offsets(subtrees);
    for (std::uint32_t n = 0; n < subtrees; ++n) {
      BuiltSubtreeRecord wire;
      std::memcpy(&wire, bytes.data() + records_at + std::uint64_t{n} * sizeof wire, sizeof wire);
      const std::uint64_t index = std::uint64_t{k} * subtrees + n;
      std::memcpy(&counts_[index * levels_ * 2], bytes.data() + counts_at + std::uint64_t{n} * levels_ * 2 * 8,
                  levels_ * 2 * 8);
      std::uint64_t size = 0;
      for (unsigned l = subtree_level_; l <= depth_; ++l)
        size += count(index, l, 0) * 8 + count(index, l, 1) * sizeof(Stored);
      if (wire.data_offset > header.data_bytes || size > header.data_bytes - wire.data_offset)
        throw Error(ErrorClass::Malformed,
                    what + " " + std::to_string(k) + ": subtree " + std::to_string(n) + " lies outside its data");
      subtree_records[n] = detail::from_wire(wire);
      data_offsets[n] = wire.data_offset;
    }
    // Checked whole before any of it is compressed into the spill file.
    const std::uint8_t* data = bytes.data() + data_at;
    parallel_for(subtrees, threads_, [&](std::uint32_t n) {
      const std::uint64_t index = std::uint64_t{k} * subtrees + n;
      std::vector<detail::PackedChunk> chunks;
      std::uint64_t at = data_offsets[n];
      for (unsigned l = subtree_level_; l <= depth_; ++l) {
        chunks.push_back(detail::pack_chunk(data + at, count(index, l, 0), 8, spill_level_));
        at += count(index, l, 0) * 8;
        chunks.push_back(detail::pack_chunk(data + at, count(index, l, 1), sizeof(Stored), spill_level_));
        at += count(index, l, 1) * sizeof(Stored);
      }
      store_subtree(index, subtree_records[n], chunks);
    });
    BuildStats slab_stats;
    slab_stats.max_abs_error = header.max_abs_error;
    slab_stats.kept = header.kept;
    slab_stats.coarsened = header.coarsened != 0;
    stats_.merge(slab_stats);
    ++slabs_done;
    build_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  StreamingResult finish(const Metadata& given_metadata, const StreamingOctreeWriter::AmendMetadata& amend) override {
    if (slabs_done != grid_[2])
      throw Error(ErrorClass::InvalidArgument,
                  path_ + ": " + std::to_string(slabs_done) + " of " + std::to_string(grid_[2]) + " slabs given");
    const auto start = std::chrono::steady_clock::now();
    LevelArrays<Stored> top(depth_);
    RegionStats ignored;
    bool ignored_kept = false;
    const NodeResult root = top_node(0, 0, 0, 0, top, ignored, ignored_kept);
    build_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    StreamingResult result;
    result.max_abs_error = stats_.max_abs_error;
    result.lossless = stats_.max_abs_error == 0.0 && !stats_.coarsened;
    result.kept_voxels = stats_.kept + (depth_ == 0 ? 1 : 0);
    result.spill_bytes = spill_.size();
    result.spill_directory = spill_.directory();
    result.build_seconds = build_seconds_;
    Metadata metadata = given_metadata;
    if (amend) amend(metadata, result);

    VolumeLayout layout = builder_.layout();
    layout.inner_count.assign(depth_ + 1, 0);
    if (root.inner) {
      for (unsigned l = 0; l < subtree_level_; ++l) layout.inner_count[l] = top.nodes[l].size();
      for (std::uint64_t s = 0; s < records_.size(); ++s)
        for (unsigned l = subtree_level_; l <= depth_; ++l) layout.inner_count[l] += count(s, l, 0);
    }
    FileWriter writer(path_, layout, options_.write.framed_blocks);
    if (writer.framed()) writer.write_metadata(metadata);  // known by now: first, as spec §15 recommends
    detail::BlockPipeline pipeline(writer, options_.write);
    const std::uint32_t block = options_.write.block_bytes;
    std::uint64_t next_child = 1;  // breadth-first first_inner_child, across levels
    std::vector<std::uint8_t> buffer;
    for (unsigned l = 0; l <= depth_; ++l) {
      detail::BlockAssembler values(pipeline, Stream::Values, l, layout.first_value(l), sizeof(Stored), block);
      if (l == 0) {
        const auto bits = static_cast<Stored>(root.bits);
        values.append(&bits, 1);
      } else if (root.inner && l <= subtree_level_) {
        values.append(top.values[l].data(), top.values[l].size());
      } else if (root.inner) {
        for_each_subtree([&](std::uint64_t s) {
          const std::uint64_t n = count(s, l, 1);
          buffer.resize(n * sizeof(Stored));
          spill_.read_chunk(spill_offset(s, l, 1), stored(s, l, 1), buffer.data(), n, sizeof(Stored));
          values.append(buffer.data(), n);
        });
      }
      values.finish();
      if (!root.inner) continue;
      detail::BlockAssembler nodes(pipeline, Stream::Nodes, l, layout.first_inner(l), 8, block);
      auto emit_nodes = [&](std::uint64_t* words, std::uint64_t n) {
        for (std::uint64_t w = 0; w < n; ++w) {
          const std::uint8_t mask = child_mask(words[w]);
          words[w] = make_node_word(mask, next_child);
          next_child += static_cast<unsigned>(__builtin_popcount(mask));
        }
        nodes.append(words, n);
      };
      if (l < subtree_level_) {
        emit_nodes(top.nodes[l].data(), top.nodes[l].size());
      } else {
        for_each_subtree([&](std::uint64_t s) {
          const std::uint64_t n = count(s, l, 0);
          std::vector<std::uint64_t> words(n);
          spill_.read_chunk(spill_offset(s, l, 0), stored(s, l, 0), words.data(), n, 8);
          emit_nodes(words.data(), n);
        });
      }
      nodes.finish();
    }
    pipeline.flush();
    writer.finish(metadata, layout.inner_count);

    result.write.file_bytes = writer.bytes_written();
    result.write.block_count = writer.block_count();
    result.write.decoded_bytes = pipeline.decoded_bytes();
    result.write.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  }

 private:
  struct Record {
    SubtreeRecord subtree;
    std::uint64_t spill_offset = 0;
  };

  // Slab k is next, and has a keep mask as every slab before it or none.
  void begin_slab(std::uint32_t k, bool with_keep) {
    if (k >= grid_[2]) throw Error(ErrorClass::InvalidArgument, path_ + ": more slabs than the volume holds");
    if (k > 0 && with_keep != with_keep_)
      throw Error(ErrorClass::InvalidArgument, path_ + ": either every slab has a keep mask or none");
    with_keep_ = with_keep;
  }

  std::uint64_t count(std::uint64_t subtree, unsigned level, int stream) const {
    return counts_[(subtree * levels_ + (level - subtree_level_)) * 2 + stream];
  }
  std::uint64_t stored(std::uint64_t subtree, unsigned level, int stream) const {
    return stored_[(subtree * levels_ + (level - subtree_level_)) * 2 + stream];
  }

  // Appends a subtree's packed chunks (per level: nodes, values) to the spill
  // file; called from several building threads at once.
  void store_subtree(std::uint64_t index, const SubtreeRecord& record, const std::vector<detail::PackedChunk>& chunks) {
    std::lock_guard<std::mutex> lock(spill_mutex_);
    records_[index] = Record{record, spill_.size()};
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      spill_.append(chunks[c].stored.data(), chunks[c].stored.size());
      stored_[index * levels_ * 2 + c] = chunks[c].stored.size();
      counts_[index * levels_ * 2 + c] = chunks[c].raw_bytes / (c % 2 == 0 ? 8 : sizeof(Stored));
    }
  }

  // Where a subtree's nodes (stream 0) or values (stream 1) of `level` lie in
  // the spill file: after its earlier levels.
  std::uint64_t spill_offset(std::uint64_t subtree, unsigned level, int stream) const {
    std::uint64_t at = records_[subtree].spill_offset;
    for (unsigned l = subtree_level_; l < level; ++l) at += stored(subtree, l, 0) + stored(subtree, l, 1);
    if (stream == 1) at += stored(subtree, level, 0);
    return at;
  }

  // Visits the subtrees in Morton order of their roots: the breadth-first
  // order of their nodes within every level.
  template <class F>
  void for_each_subtree(F&& visit) const {
    const std::uint64_t total = std::uint64_t{1} << (3 * subtree_level_);
    for (std::uint64_t t = 0; t < total; ++t) {
      std::uint32_t i, j, k;
      detail::morton_decode(subtree_level_, t, i, j, k);
      if (i < grid_[0] && j < grid_[1] && k < grid_[2]) visit((std::uint64_t{k} * grid_[1] + j) * grid_[0] + i);
    }
  }

  NodeResult top_node(unsigned level, std::uint32_t i, std::uint32_t j, std::uint32_t k, LevelArrays<Stored>& out,
                      RegionStats& stats, bool& any_kept) {
    if (level == subtree_level_) {
      if (i >= grid_[0] || j >= grid_[1] || k >= grid_[2]) return NodeResult{};
      const Record& r = records_[(std::uint64_t{k} * grid_[1] + j) * grid_[0] + i];
      stats = r.subtree.stats;
      any_kept = r.subtree.any_kept;
      return r.subtree.root;
    }
    const std::uint64_t weight = builder_.layout().weight(level, i, j, k);
    if (weight == 0) return NodeResult{};
    NodeResult child[8];
    stats = RegionStats{};
    any_kept = false;
    for (unsigned c = 0; c < 8; ++c) {
      RegionStats child_stats;
      bool child_kept = false;
      child[c] = top_node(level + 1, 2 * i + (c & 1u), 2 * j + ((c >> 1) & 1u), 2 * k + ((c >> 2) & 1u), out,
                          child_stats, child_kept);
      stats.merge(child_stats);
      any_kept = any_kept || child_kept;
    }
    if (with_keep_ && !any_kept) return builder_.leaf_from_stats(stats, weight, stats_);
    return builder_.combine(level, child, weight, out, stats_);
  }

  std::string path_;
  StreamingOptions options_;
  detail::Builder<Source, Stored> builder_;
  SlabGrid slab_grid_;
  detail::SpillFile spill_;
  int spill_level_ = 1;
  std::mutex spill_mutex_;
  unsigned depth_ = 0;
  unsigned subtree_level_ = 0;
  unsigned levels_ = 0;
  unsigned threads_ = 1;
  std::uint32_t grid_[3] = {1, 1, 1};
  std::vector<Record> records_;
  std::vector<std::uint64_t> counts_;  // per subtree, level, stream (nodes, values): elements
  std::vector<std::uint64_t> stored_;  // the same chunks' bytes in the spill file
  BuildStats stats_;
  bool with_keep_ = false;
  double build_seconds_ = 0.0;
};

template <typename Source>
std::unique_ptr<StreamingOctreeWriter::Impl> make_engine(const std::string& path, const Dims& dims,
                                                         const StreamingOptions& options) {
  const std::uint32_t slab = detail::choose_slab_slices(dims, options);
  if (options.build.encoding == ValueEncoding::Float32)
    return std::make_unique<Engine<Source, std::uint32_t>>(path, dims, options, slab);
  return std::make_unique<Engine<Source, std::uint16_t>>(path, dims, options, slab);
}

}  // namespace

std::string spill_directory_for(const std::string& output_path, const std::string& spill_directory) {
  if (!spill_directory.empty()) return spill_directory;
  const char* tmpdir = std::getenv("TMPDIR");
  if (tmpdir != nullptr && *tmpdir != '\0') return tmpdir;
  return directory_of(output_path);
}

struct StreamingState {
  std::string path;
  Dims dims;
  StreamingOptions options;
};

StreamingOctreeWriter::StreamingOctreeWriter(const std::string& path, const Dims& dims,
                                             const StreamingOptions& options) {
  detail::check_streaming_options(dims, options);
  // The spill file's directory is tried now, before any slab is computed: an
  // unnamed file, closed at once.
  detail::SpillFile probe(spill_directory_for(path, options.spill_directory));
  // The engine is made for the sample type of the first slab; until then keep
  // what it needs.
  pending_ = std::make_unique<StreamingState>(StreamingState{path, dims, options});
}

StreamingOctreeWriter::~StreamingOctreeWriter() = default;

std::uint32_t StreamingOctreeWriter::slab_slices() const {
  return impl_ ? impl_->slab_slices : detail::choose_slab_slices(pending_->dims, pending_->options);
}

std::uint64_t StreamingOctreeWriter::index_bytes() const {
  return detail::subtree_index_bytes(impl_ ? impl_->dims : pending_->dims, slab_slices());
}

std::uint32_t StreamingOctreeWriter::next_slab_first() const {
  return impl_ ? impl_->slabs_done * impl_->slab_slices : 0;
}

std::uint32_t StreamingOctreeWriter::next_slab_count() const {
  const Dims& d = impl_ ? impl_->dims : pending_->dims;
  const std::uint32_t first = next_slab_first();
  return first >= d[2] ? 0 : std::min(slab_slices(), d[2] - first);
}

void StreamingOctreeWriter::add_slab(const float* samples, const std::uint8_t* keep) {
  if (!impl_) impl_ = make_engine<float>(pending_->path, pending_->dims, pending_->options);
  if (!impl_->is_float) throw Error(ErrorClass::InvalidArgument, "streaming: slabs must all have one sample type");
  impl_->add(samples, keep);
}

void StreamingOctreeWriter::add_slab(const std::uint16_t* samples, const std::uint8_t* keep) {
  if (!impl_) impl_ = make_engine<std::uint16_t>(pending_->path, pending_->dims, pending_->options);
  if (impl_->is_float) throw Error(ErrorClass::InvalidArgument, "streaming: slabs must all have one sample type");
  impl_->add(samples, keep);
}

void StreamingOctreeWriter::add_built_slab(const BuiltSlab& built) {
  // The sample type the slab was built from decides the engine, as add_slab's does.
  bool from_float = true;
  if (built.bytes.size() >= sizeof(BuiltSlabHeader)) {
    BuiltSlabHeader header;
    std::memcpy(&header, built.bytes.data(), sizeof header);
    from_float = header.source_is_float != 0;
  }
  if (!impl_)
    impl_ = from_float ? make_engine<float>(pending_->path, pending_->dims, pending_->options)
                       : make_engine<std::uint16_t>(pending_->path, pending_->dims, pending_->options);
  impl_->add_built(built);
}

StreamingResult StreamingOctreeWriter::finish(const Metadata& metadata, const AmendMetadata& amend) {
  if (!impl_) throw Error(ErrorClass::InvalidArgument, "streaming: finish() before any slab");
  return impl_->finish(metadata, amend);
}

}  // namespace ivol
