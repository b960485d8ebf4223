#include "ivol/bricked_writer.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <thread>

#include "brick_grid.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/masked_codec.hpp"
#include "ivol/predicted_codec.hpp"
#include "ivol/top_byte_codec.hpp"
#include "layout.hpp"
#include "stored_levels.hpp"
#include "thread_parts.hpp"

namespace ivol {

namespace {

// A brick's values as the little-endian bytes codec 6 codes.
template <class T>
std::vector<std::uint8_t> encode_top_byte_of(const T* values, const Dims& e, std::size_t limit) {
  const std::size_t n = std::size_t{e[0]} * e[1] * e[2];
  std::vector<std::uint8_t> bytes(sizeof(T) * n);
  for (std::size_t v = 0; v < n; ++v) layout::store<T>(bytes.data() + sizeof(T) * v, values[v]);
  std::vector<std::uint8_t> best = encode_top_byte(bytes.data(), e, sizeof(T), limit);
  // float32 is tried only at the smallest settings: there the classes of 1
  // and 2 are tried too, each against the smallest so far. The 64³ bricks
  // of noise-free reconstructions learn such fine classes; with them codec
  // 6 won 11 of the connector board's 64 bricks instead of 6, 21.8 KB
  // smaller in all (bench/RESULTS.md, "Codec 6's classes").
  if constexpr (sizeof(T) == 4)
    for (const unsigned step : {1u, 2u}) {
      std::vector<std::uint8_t> finer =
          encode_top_byte(bytes.data(), e, sizeof(T), best.empty() ? limit : best.size(), step);
      if (!finer.empty()) best = std::move(finer);
    }
  return best;
}

// The order-0 entropy of a brick's low and high bytes, in bytes, estimated
// from every fourth value: about what codec 2 spends where zstd finds no
// matches. (Counting every value was 4 % of a binary16 conversion; the
// estimate needs no such precision, its threshold below has 10 % to spare.)
double byte_plane_entropy(const std::uint16_t* values, std::size_t n) {
  // Two counts per byte value, taken in turn: with one, a run of equal
  // high bytes chained each increment to the last.
  std::array<std::array<std::uint32_t, 256>, 2> low{}, high{};
  std::size_t sampled = 0;
  for (std::size_t i = 0; i < n; i += 4, ++sampled)
    ++low[sampled & 1][values[i] & 0xFF], ++high[sampled & 1][values[i] >> 8];
  double bits = 0;
  for (const auto* counts : {&low, &high})
    for (unsigned b = 0; b < 256; ++b) {
      const std::uint32_t c = (*counts)[0][b] + (*counts)[1][b];
      if (c) bits += c * std::log2(static_cast<double>(sampled) / c);
    }
  return bits / 8 * (static_cast<double>(n) / static_cast<double>(sampled));
}

// Whether codec 2's trial (and with it codec 6's) can be skipped: where
// codec 3 spends 6 bits a voxel or more and is under 0.9 of the byte
// planes' order-0 entropy. Codec 2 beats that entropy only with zstd's
// matches, which such busy bricks do not have: on the six 256³ phantoms
// (noise-free and noisy, binary16 and uint16, 32³ and 64³ bricks) this
// skips a quarter of the trials and no brick that codec 2 or 6 won
// (bench/RESULTS.md, "Skipping codec 2's trial"; bench/plane_trial_study).
bool planes_cannot_win(const std::uint16_t* values, std::size_t n, std::size_t predicted_bytes) {
  if (8 * predicted_bytes < 6 * n) return false;
  return static_cast<double>(predicted_bytes) < 0.9 * byte_plane_entropy(values, n);
}

}  // namespace

struct BrickedGridWriter::Impl {
  Impl(const std::string& path, const Dims& dims, const BrickedOptions& o)
      : options(o),
        grid(dims, o.brick_log2),
        file(path, layout_of(dims, o), true),
        levels(dims, o.brick_log2, o.encoding, o.first_stored_level),
        start(std::chrono::steady_clock::now()) {}

  static VolumeLayout layout_of(const Dims& dims, const BrickedOptions& o) {
    if (o.brick_log2 < 1 || o.brick_log2 > layout::kMaxBrickLog2)
      throw Error(ErrorClass::InvalidArgument, "bricked grid: brick_log2 " + std::to_string(o.brick_log2) +
                                                   " is outside 1 .. " + std::to_string(layout::kMaxBrickLog2));
    VolumeLayout v;
    v.kind = StructureKind::Bricked;
    v.cell_log2 = static_cast<std::uint8_t>(o.brick_log2);
    v.dims = dims;
    v.depth = depth_for(dims);
    v.encoding = o.encoding;
    v.value_scale = o.value_scale;
    v.value_offset = o.value_offset;
    v.inner_count.assign(v.depth + 1, 0);
    return v;
  }

  // One brick, cut from the layer and encoded: 16-bit values as the
  // smallest of codec 3, codec 2 and codec 4, float32 values as their byte
  // planes (codec 2; codecs 3 and 4 hold 16-bit values), either stored when
  // nothing is smaller (random bits). `layer` holds the brick layer's
  // slices of a volume of `d` voxels in bricks `g`: the full-resolution
  // grid, or a stored level of detail's.
  template <class T>
  EncodedBlock encode(const T* layer, const Dims& d, const detail::BrickGrid& g, std::uint32_t i, std::uint32_t j,
                      std::uint32_t k) const {
    const Dims e = g.extent(i, j, k);
    const std::uint64_t edge = g.edge();
    std::vector<T> brick(std::size_t{e[0]} * e[1] * e[2]);
    std::size_t n = 0;
    for (std::uint32_t z = 0; z < e[2]; ++z)
      for (std::uint32_t y = 0; y < e[1]; ++y) {
        const T* row = layer + (std::uint64_t{z} * d[1] + j * edge + y) * d[0] + i * edge;
        std::copy(row, row + e[0], brick.data() + n);
        n += e[0];
      }
    const std::uint64_t first = g.first_value(i, j, k);
    WriteOptions w;
    w.zstd_level = options.zstd_level;
    EncodedBlock block;
    // Whether codec 6 is worth a trial on this brick (below).
    bool try_top_byte = true;
    if constexpr (sizeof(T) == 4) {
      block = encode_block(Stream::Values, 0, first, static_cast<std::uint32_t>(n), 4, brick.data(), w);
      // float32 bricks of codec 6 are 1-2 % smaller than codec 2's but
      // decode at about 150 MB/s a core against zstd's 1 GB/s and more: a
      // trade for those who ask for the smallest files (the levels from
      // which planes are a frame each), not the default's (bench/RESULTS.md,
      // "Codec 6").
      try_top_byte = options.zstd_level >= kPlaneFramesFromLevel;
    } else {
      if (!options.predicted)
        return encode_block(Stream::Values, 0, first, static_cast<std::uint32_t>(n), 2, brick.data(), w);
      block.stream = Stream::Values;
      block.first_element = first;
      block.element_count = static_cast<std::uint32_t>(n);
      PredictedOptions p;
      p.zstd_level = residual_zstd_level(options.zstd_level);
      p.entropy = options.entropy;
      block.bytes = encode_predicted(brick.data(), e, options.encoding, p);
      block.codec = Codec::Predicted;
      // Where noise dominates, no predictor beats the values' own byte planes:
      // the smaller of codec 3 and codec 2 is kept (and stored below either).
      // Up to level 3 codec 2 is tried at zstd level 1, and made again at the
      // asked level only where it wins (2-6 % of a noise-free CT volume's
      // bricks, 25-70 % with Poisson noise): the trial was a tenth of a
      // binary16 conversion's time, and the files are the same to 0.002 %
      // (bench/RESULTS.md, issue 22).
      WriteOptions trial = w;
      if (w.zstd_level <= 3) trial.zstd_level = 1;
      if (w.zstd_level <= 3 && planes_cannot_win(brick.data(), n, block.bytes.size())) {
        try_top_byte = false;
      } else {
        EncodedBlock planes =
            encode_block(Stream::Values, 0, first, static_cast<std::uint32_t>(n), 2, brick.data(), trial);
        // Codec 6 wins where prediction does not help: up to level 3 it is
        // tried only where zstd's byte planes come within 5 % of codec 3. On
        // the six 256³ phantoms that kept 94-100 % of what trying every brick
        // saved, and skipped 80 % of the trials on the noise-free pencil
        // holder, where codec 6 wins none (bench/RESULTS.md, "Codec 6").
        if (w.zstd_level <= 3) try_top_byte = 100 * planes.bytes.size() < 105 * block.bytes.size();
        if (trial.zstd_level != w.zstd_level && planes.bytes.size() < block.bytes.size()) {
          EncodedBlock asked =
              encode_block(Stream::Values, 0, first, static_cast<std::uint32_t>(n), 2, brick.data(), w);
          if (asked.bytes.size() <= planes.bytes.size()) planes = std::move(asked);
        }
        if (planes.bytes.size() < block.bytes.size()) block = std::move(planes);
      }
      // Who asked for zstd's entropy coding or coder 3 asked for their
      // decoding speed, which codec 6 does not have.
      if (options.entropy == PredictedOptions::Entropy::ZstdPlanes ||
          options.entropy == PredictedOptions::Entropy::Lanes)
        try_top_byte = false;
      // Where one value (an object-fidelity file's background) fills an eighth
      // of the brick or more, codec 4 stores only the others, behind a mask;
      // a brick of that value alone is 4 bytes (bench/RESULTS.md, issue 22).
      const CommonValue common = likely_background(brick.data(), n);
      if (common.count >= n / 8) {
        std::vector<std::uint8_t> masked = encode_masked(brick.data(), n, common.value, options.zstd_level);
        if (masked.size() < block.bytes.size()) block.bytes = std::move(masked), block.codec = Codec::Masked;
      }
    }
    // Where the best so far spends more than a quarter of the values' bits
    // (noise), codec 6 is tried: the top byte coded in its neighbours'
    // context, the bytes below as they are (spec §7.4). It stops as soon as
    // it cannot be smaller. On the noisy 256³ phantoms it won 27-63 % of the
    // bricks, on noise-free ones up to half of a lattice's (bench/RESULTS.md,
    // issue 22, "Codec 6").
    if (try_top_byte && block.codec != Codec::Masked && block.bytes.size() > sizeof(T) * n / 4) {
      std::vector<std::uint8_t> top = encode_top_byte_of(brick.data(), e, block.bytes.size());
      if (!top.empty()) block.bytes = std::move(top), block.codec = Codec::TopByte;
    }
    if (block.bytes.size() >= sizeof(T) * n) {
      block.codec = Codec::Stored;
      block.bytes.resize(sizeof(T) * n);
      for (std::size_t v = 0; v < n; ++v) layout::store<T>(block.bytes.data() + sizeof(T) * v, brick[v]);
    }
    block.crc = crc32c(block.bytes.data(), block.bytes.size());
    return block;
  }

  const Dims& dims() const { return dims_; }

  // Encodes a layer of bricks on the writer's threads, in brick order.
  template <class T>
  std::vector<EncodedBlock> encode_layer(const T* values, const Dims& d, const detail::BrickGrid& g,
                                         std::uint32_t k) const;
  // add_layer's work for either width of stored values.
  template <class T>
  void add_layer(const T* values);

  BrickedOptions options;
  detail::BrickGrid grid;
  Dims dims_{};
  FileWriter file;
  detail::StoredLevels levels;
  std::uint32_t next_layer = 0;  // brick layer index along z
  std::uint64_t decoded_bytes = 0;
  std::chrono::steady_clock::time_point start;
};

namespace {

// Bricks of the background alone that follow one another in the layer (the
// same 4-byte codec 4 payload) become one block (spec §7.3): in an
// object-fidelity file they are most bricks, and a block each cost 68 bytes
// of block header, payload and index entry. A run stays within 4 MiB of
// values, so that reading one voxel of it decodes no more than that.
std::vector<EncodedBlock> merge_background_runs(std::vector<EncodedBlock> blocks) {
  constexpr std::uint64_t kMaxRunValues = (4u << 20) / 2;
  auto background_only = [](const EncodedBlock& b) {
    return b.codec == Codec::Masked && b.bytes.size() == kMaskedHeaderSize;
  };
  std::vector<EncodedBlock> out;
  for (EncodedBlock& b : blocks) {
    if (!out.empty() && background_only(b) && background_only(out.back()) && out.back().bytes == b.bytes &&
        std::uint64_t{out.back().element_count} + b.element_count <= kMaxRunValues) {
      out.back().element_count += b.element_count;
      continue;
    }
    out.push_back(std::move(b));
  }
  return out;
}

}  // namespace

BrickedGridWriter::BrickedGridWriter(const std::string& path, const Dims& dims, const BrickedOptions& options)
    : impl_(std::make_unique<Impl>(path, dims, options)) {
  impl_->dims_ = dims;
}

BrickedGridWriter::~BrickedGridWriter() = default;

std::uint32_t BrickedGridWriter::next_layer_first() const {
  return static_cast<std::uint32_t>(std::uint64_t{impl_->next_layer} * impl_->grid.edge());
}

std::uint32_t BrickedGridWriter::next_layer_count() const {
  if (impl_->next_layer >= impl_->grid.bricks()[2]) return 0;
  return impl_->grid.extent(0, 0, impl_->next_layer)[2];
}

template <class T>
std::vector<EncodedBlock> BrickedGridWriter::Impl::encode_layer(const T* values, const Dims& d,
                                                                const detail::BrickGrid& g, std::uint32_t k) const {
  const std::uint32_t nx = g.bricks()[0], ny = g.bricks()[1];
  const std::size_t count = std::size_t{nx} * ny;
  std::vector<EncodedBlock> blocks(count);
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t b; (b = next++) < count;) blocks[b] = encode(values, d, g, b % nx, b / nx, k);
  };
  const unsigned hardware = std::max(1u, std::thread::hardware_concurrency());
  const unsigned threads =
      static_cast<unsigned>(std::min<std::size_t>(options.threads ? options.threads : hardware, count));
  detail::run_parts(threads, [&](unsigned) {
    try {
      work();
    } catch (...) {
      next = count;  // the other parts stop early
      throw;
    }
  });
  return merge_background_runs(std::move(blocks));
}

void BrickedGridWriter::write_early_metadata(const Metadata& metadata) {
  if (impl_->next_layer != 0)
    throw Error(ErrorClass::InvalidArgument, "bricked grid: early metadata after the first layer");
  impl_->file.write_early_metadata(metadata);
}

void BrickedGridWriter::add_layer(const std::uint16_t* values) {
  if (impl_->options.encoding == ValueEncoding::Float32)
    throw Error(ErrorClass::InvalidArgument, "bricked grid: 16-bit values given for a float32 grid");
  impl_->add_layer(values);
}

void BrickedGridWriter::add_layer(const std::uint32_t* values) {
  if (impl_->options.encoding != ValueEncoding::Float32)
    throw Error(ErrorClass::InvalidArgument, "bricked grid: float32 values given for a 16-bit grid");
  impl_->add_layer(values);
}

template <class T>
void BrickedGridWriter::Impl::add_layer(const T* values) {
  Impl& m = *this;
  if (m.next_layer >= m.grid.bricks()[2])
    throw Error(ErrorClass::InvalidArgument, "bricked grid: a layer after the last");
  // The stored levels of detail take the layer's voxels on a thread of
  // their own while its bricks are encoded; a layer of a level's bricks is
  // written once its last slice is summed (spec §15), after the layer.
  struct LevelLayer {
    unsigned level;
    Dims dims;
    std::uint32_t layer;
    std::vector<T> values;
  };
  std::vector<LevelLayer> level_layers;
  std::exception_ptr level_failure;
  std::thread summing;
  if (!m.levels.empty())
    summing = std::thread([&, z0 = static_cast<std::uint32_t>(std::uint64_t{m.next_layer} * m.grid.edge()),
                           count = m.grid.extent(0, 0, m.next_layer)[2]] {
      try {
        m.levels.add(values, z0, count,
                     [&](unsigned level, const Dims& d, std::uint32_t layer, const std::uint32_t* level_values) {
                       const std::size_t n =
                           std::size_t{d[0]} * d[1] *
                           std::min<std::uint64_t>(std::uint64_t{1} << m.options.brick_log2,
                                                   d[2] - (std::uint64_t{layer} << m.options.brick_log2));
                       level_layers.push_back({level, d, layer, {level_values, level_values + n}});
                     });
      } catch (...) {
        level_failure = std::current_exception();
      }
    });
  std::vector<EncodedBlock> blocks;
  try {
    blocks = m.encode_layer(values, m.dims_, m.grid, m.next_layer);
  } catch (...) {
    if (summing.joinable()) summing.join();
    throw;
  }
  if (summing.joinable()) summing.join();
  if (level_failure) std::rethrow_exception(level_failure);
  for (const EncodedBlock& b : blocks) {
    m.file.append(b);
    m.decoded_bytes += sizeof(T) * std::uint64_t{b.element_count};
  }
  for (const LevelLayer& l : level_layers) {
    const detail::BrickGrid level_grid(l.dims, m.options.brick_log2);
    for (EncodedBlock& b : m.encode_layer(l.values.data(), l.dims, level_grid, l.layer)) {
      b.stream = Stream::StoredLevel;
      b.level = static_cast<std::uint8_t>(l.level);
      m.file.append(b);
      m.decoded_bytes += sizeof(T) * std::uint64_t{b.element_count};
    }
  }
  ++m.next_layer;
}

WriteStats BrickedGridWriter::finish(const Metadata& metadata) {
  Impl& m = *impl_;
  if (next_layer_count() != 0)
    throw Error(ErrorClass::InvalidArgument, "bricked grid: finish() before the last layer was added");
  m.file.finish(metadata, std::vector<std::uint64_t>(depth_for(m.dims_) + 1, 0));
  WriteStats stats;
  stats.file_bytes = m.file.bytes_written();
  stats.decoded_bytes = m.decoded_bytes;
  stats.block_count = m.file.block_count();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - m.start).count();
  return stats;
}

}  // namespace ivol
