#include "hostile_files.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <stdexcept>

#include "ivol/build.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/writer.hpp"

namespace ivol::test::hostile {
namespace {

const std::string kMetadata =
    R"({"voxel_size":[1,1,1],"unit":"mm","origin":[0,0,0],"value":{"quantity":"grey_value"}})";

template <class T>
void put(std::vector<std::uint8_t>& out, std::size_t at, T v) {
  std::memcpy(out.data() + at, &v, sizeof v);
}

struct Block {
  std::uint8_t stream = 3, codec = 0, level = 0, flags = 0;
  std::uint64_t first = 0;
  std::uint32_t count = 0;
  std::uint32_t stored_size = 0;  // may exceed bytes.size(): the rest is a hole
  std::uint32_t crc = 0;
  std::vector<std::uint8_t> bytes;
};

// A block of `count` elements of `width` bytes: zstd (codec 1) when that is
// smaller, else stored; its CRC valid.
Block encoded(std::uint8_t stream, std::uint8_t level, std::uint64_t first, std::uint32_t count, std::size_t width,
              const void* data) {
  WriteOptions options;
  options.byte_planes = false;
  options.threads = 1;
  EncodedBlock e = encode_block(static_cast<Stream>(stream), level, first, count, width, data, options);
  Block b;
  b.stream = stream;
  b.level = level;
  b.first = first;
  b.count = count;
  b.codec = static_cast<std::uint8_t>(e.codec);
  b.stored_size = static_cast<std::uint32_t>(e.bytes.size());
  b.crc = e.crc;
  b.bytes = std::move(e.bytes);
  return b;
}

Block metadata_block(const std::string& text) {
  return encoded(1, 0, 0, static_cast<std::uint32_t>(text.size()), 1, text.data());
}

struct Container {
  std::uint8_t kind = 1;      // structure_kind
  std::uint8_t encoding = 3;  // float32
  std::uint8_t depth = 0;
  std::uint32_t dims[3] = {1, 1, 1};
  std::vector<std::uint64_t> inner_count;  // depth + 1 entries
  std::vector<Block> blocks;
  std::uint64_t claimed_index_size = 0;  // non-zero: the footer claims this (the rest a hole)

  // Header, blocks, index and footer with valid CRCs (but for blocks whose
  // stored bytes are partly a hole: their CRC is whatever the caller set).
  void write(const std::string& path) const {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) throw std::runtime_error(path + ": cannot create");
    auto at = [&](std::uint64_t offset, const std::vector<std::uint8_t>& bytes) {
      if (!bytes.empty() &&
          ::pwrite(fd, bytes.data(), bytes.size(), static_cast<off_t>(offset)) != static_cast<ssize_t>(bytes.size()))
        throw std::runtime_error(path + ": write failed");
    };
    std::vector<std::uint8_t> header(40, 0);
    const unsigned char sig[8] = {0x89, 'I', 'V', 'O', 'L', 0x0D, 0x0A, 0x0A};
    std::memcpy(header.data(), sig, 8);
    put<std::uint16_t>(header, 8, 1);
    put<std::uint16_t>(header, 10, 2);
    put<std::uint32_t>(header, 12, 40);
    put<std::uint32_t>(header, 36, crc32c(header.data(), 36));
    at(0, header);

    std::uint64_t offset = 40;
    std::vector<std::uint8_t> index(48 + 8 * (depth + 1) + 32 * blocks.size(), 0);
    std::memcpy(index.data(), "IVIX", 4);
    put<std::uint32_t>(index, 4, 48);
    index[8] = kind;
    index[9] = encoding;
    index[10] = depth;
    for (int a = 0; a < 3; ++a) put<std::uint32_t>(index, 12 + 4 * a, dims[a]);
    put<double>(index, 24, 1.0);
    put<double>(index, 32, 0.0);
    put<std::uint32_t>(index, 40, static_cast<std::uint32_t>(blocks.size()));
    put<std::uint32_t>(index, 44, 32);
    for (unsigned l = 0; l <= depth; ++l) put<std::uint64_t>(index, 48 + 8 * l, inner_count.at(l));
    for (std::size_t b = 0; b < blocks.size(); ++b) {
      const Block& blk = blocks[b];
      const std::size_t e = 48 + 8 * (depth + 1) + 32 * b;
      put<std::uint64_t>(index, e, offset);
      put<std::uint64_t>(index, e + 8, blk.first);
      put<std::uint32_t>(index, e + 16, blk.count);
      put<std::uint32_t>(index, e + 20, blk.stored_size);
      put<std::uint32_t>(index, e + 24, blk.crc);
      index[e + 28] = blk.stream;
      index[e + 29] = blk.codec;
      index[e + 30] = blk.flags;
      index[e + 31] = blk.level;
      at(offset, blk.bytes);
      offset += blk.stored_size;
    }
    const std::uint64_t index_size = claimed_index_size ? claimed_index_size : index.size();
    if (!claimed_index_size) at(offset, index);
    std::vector<std::uint8_t> footer(32, 0);
    put<std::uint64_t>(footer, 0, offset);
    put<std::uint64_t>(footer, 8, index_size);
    put<std::uint32_t>(footer, 16, claimed_index_size ? 0u : crc32c(index.data(), index.size()));
    put<std::uint32_t>(footer, 20, crc32c(footer.data(), 20));
    std::memcpy(footer.data() + 24, "IVOL_END", 8);
    at(offset + index_size, footer);
    ::close(fd);
  }
};

// A 1x1x1 float32 octree with `metadata`: the smallest file around it.
Container one_voxel(const std::string& metadata) {
  Container c;
  c.inner_count = {0};
  const float value = 1.0f;
  c.blocks.push_back(metadata_block(metadata));
  c.blocks.push_back(encoded(3, 0, 0, 1, 4, &value));
  return c;
}

// An octree of depth 10 (1024^3, 4 GiB as float32) whose nodes of each level
// all name the same eight children: 73 inner nodes, 585 values, 3 KB; every
// rule a single node is checked against holds, only the breadth-first
// numbering of spec §8.3 does not.
Container dag_octree() {
  Container c;
  c.depth = 10;
  c.dims[0] = c.dims[1] = c.dims[2] = 1024;
  c.inner_count = {1, 8, 8, 8, 8, 8, 8, 8, 8, 8, 0};
  std::vector<std::uint64_t> first_inner(12, 0);
  for (unsigned l = 0; l <= 10; ++l) first_inner[l + 1] = first_inner[l] + c.inner_count[l];
  c.blocks.push_back(metadata_block(kMetadata));
  for (unsigned l = 0; l < 10; ++l) {
    const std::uint64_t mask = l + 1 == 10 ? 0 : 0xFF;
    const std::uint64_t word = (mask << 56) | first_inner[l + 1];
    const std::vector<std::uint64_t> words(c.inner_count[l], word);
    c.blocks.push_back(encoded(2, static_cast<std::uint8_t>(l), first_inner[l],
                               static_cast<std::uint32_t>(words.size()), 8, words.data()));
  }
  std::uint64_t first_value = 0;
  for (unsigned l = 0; l <= 10; ++l) {
    const std::uint64_t count = l == 0 ? 1 : 8 * c.inner_count[l - 1];
    const std::vector<float> zeros(count, 0.0f);
    c.blocks.push_back(
        encoded(3, static_cast<std::uint8_t>(l), first_value, static_cast<std::uint32_t>(count), 4, zeros.data()));
    first_value += count;
  }
  return c;
}

// A regular grid of 1024x1024x512 zeros (float32): 32 values blocks of 64
// MiB decoded (2 GiB), about 2 KB of zstd each. A valid file.
Container regular_zeros() {
  Container c;
  c.kind = 2;
  c.depth = 10;
  c.dims[0] = c.dims[1] = 1024;
  c.dims[2] = 512;
  c.inner_count.assign(11, 0);
  c.blocks.push_back(metadata_block(kMetadata));
  constexpr std::uint32_t kPerBlock = 1u << 24;  // 64 MiB of float32
  const std::vector<float> zeros(kPerBlock, 0.0f);
  const Block one = encoded(3, 0, 0, kPerBlock, 4, zeros.data());
  for (std::uint64_t b = 0; b < 32; ++b) {
    Block blk = one;
    blk.first = b * kPerBlock;
    c.blocks.push_back(std::move(blk));
  }
  return c;
}

// A rectilinear grid of 2^29 voxels per side made of one cell: a valid
// file of a few hundred bytes.
Container rectilinear_one_cell() {
  Container c;
  c.kind = 3;
  c.depth = 29;
  const std::uint32_t n = 1u << 29;
  c.dims[0] = c.dims[1] = c.dims[2] = n;
  c.inner_count.assign(30, 0);
  c.blocks.push_back(metadata_block(kMetadata));
  const std::uint32_t borders[6] = {0, n, 0, n, 0, n};
  c.blocks.push_back(encoded(4, 0, 0, 6, 4, borders));
  const float value = 2.5f;
  c.blocks.push_back(encoded(3, 0, 0, 1, 4, &value));
  return c;
}

// 160^3 float32 noise (no two neighbours alike, so every voxel is a leaf)
// written by libformat in 16 KiB blocks, then 40 % of its block bytes zeroed.
void salvage_file(const std::string& path) {
  const Dims dims{160, 160, 160};
  std::vector<float> volume(voxel_count(dims));
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> noise(0.0f, 1.0f);
  for (float& v : volume) v = noise(rng);
  WriteOptions options;
  options.threads = 1;
  write_octree(build_octree(volume.data(), dims, BuildOptions{}).octree, Metadata{}, path, options);
  volume = {};
  const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(path + ": cannot open");
  const off_t size = ::lseek(fd, 0, SEEK_END);
  const std::vector<std::uint8_t> zeros(static_cast<std::size_t>(size * 2 / 5), 0);
  if (::pwrite(fd, zeros.data(), zeros.size(), size / 4) != static_cast<ssize_t>(zeros.size()))
    throw std::runtime_error(path + ": write failed");
  ::close(fd);
}

}  // namespace

std::string deep_metadata(std::size_t depth, bool arrays) {
  std::string text = kMetadata.substr(0, kMetadata.size() - 1) + R"(,"user":{"deep":)";
  for (std::size_t d = 0; d < depth; ++d) text += arrays ? "[" : R"({"a":)";
  text += "1";
  text.append(depth, arrays ? ']' : '}');
  return text + "}}";
}

void write_one_voxel(const std::string& metadata, const std::string& path) { one_voxel(metadata).write(path); }

std::vector<HostileFile> catalogue() {
  return {
      {"deep_json_objects", "metadata objects nested 100 000 deep (recursion in every JSON parser and printer)"},
      {"deep_json_arrays", "metadata arrays nested 100 000 deep"},
      {"dag_octree", "every node of a level names the same children: 4 GiB of voxels from 73 nodes"},
      {"zstd_block_4gib", "a values block claiming 4 GiB stored for 4 decoded bytes", true, true},
      {"index_6gib", "the footer claims a 6 GiB index after 200 bytes of blocks", true, true},
      {"unknown_stream_2gib", "an ignorable block of an unknown stream of 2 GiB, CRC wrong", false, true},
      {"regular_grid_2gib", "a valid 1024x1024x512 regular grid in 32 blocks of 64 MiB (zeros)", false},
      {"rectilinear_2p29", "a valid rectilinear grid of 2^29 voxels per side, one cell", false},
      {"salvage_zeroed", "160^3 noise with 40 % of its blocks zeroed (for extract --salvage)", false},
  };
}

void write_full_octree(const std::string& path, unsigned shared_from) {
  // Depth 6: levels 0..5 inner (8^l nodes each), level 6 the voxels.
  Container c;
  c.depth = 6;
  c.dims[0] = c.dims[1] = c.dims[2] = 64;
  std::vector<std::uint64_t> first_inner(8, 0);
  for (unsigned l = 0; l <= 6; ++l) {
    c.inner_count.push_back(l < 6 ? std::uint64_t{1} << (3 * l) : 0);
    first_inner[l + 1] = first_inner[l] + c.inner_count[l];
  }
  c.blocks.push_back(metadata_block(kMetadata));
  for (unsigned l = 0; l < 6; ++l) {
    std::vector<std::uint64_t> words(c.inner_count[l]);
    for (std::uint64_t p = 0; p < words.size(); ++p) {
      const std::uint64_t mask = l + 1 == 6 ? 0 : 0xFF;
      std::uint64_t first = l + 1 == 6 ? first_inner[6] : first_inner[l + 1] + 8 * p;
      // Level-4 nodes shared_from .. 15 (of the second subtree of level 3)
      // name the children of the node before them, and so on.
      if (shared_from && l == 4 && p >= shared_from && p < 16) first -= 8;
      words[p] = (mask << 56) | first;
    }
    // Blocks of 64 node words: a subtree's nodes span several.
    for (std::uint64_t at = 0; at < words.size(); at += 64) {
      const auto n = static_cast<std::uint32_t>(std::min<std::uint64_t>(64, words.size() - at));
      c.blocks.push_back(encoded(2, static_cast<std::uint8_t>(l), first_inner[l] + at, n, 8, words.data() + at));
    }
  }
  std::uint64_t first_value = 0;
  for (unsigned l = 0; l <= 6; ++l) {
    const std::uint64_t count = l == 0 ? 1 : 8 * c.inner_count[l - 1];
    std::vector<float> values(count);
    for (std::uint64_t i = 0; i < count; ++i) values[i] = static_cast<float>(first_value + i);
    for (std::uint64_t at = 0; at < count; at += 1000) {
      const auto n = static_cast<std::uint32_t>(std::min<std::uint64_t>(1000, count - at));
      c.blocks.push_back(encoded(3, static_cast<std::uint8_t>(l), first_value + at, n, 4, values.data() + at));
    }
    first_value += count;
  }
  c.write(path);
}

void write(const std::string& name, const std::string& path) {
  if (name == "deep_json_objects" || name == "deep_json_arrays") {
    one_voxel(deep_metadata(100000, name == "deep_json_arrays")).write(path);
  } else if (name == "dag_octree") {
    dag_octree().write(path);
  } else if (name == "zstd_block_4gib") {
    Container c = one_voxel(kMetadata);
    Block& values = c.blocks[1];
    values.codec = 1;
    values.stored_size = 0xFFFFFF00u;  // a zstd frame of 4 bytes is at most 67 bytes
    c.write(path);
  } else if (name == "index_6gib") {
    Container c = one_voxel(kMetadata);
    c.claimed_index_size = 6ull << 30;
    c.write(path);
  } else if (name == "unknown_stream_2gib") {
    Container c = one_voxel(kMetadata);
    Block unknown;
    unknown.stream = 200;
    unknown.flags = 1;  // ignorable
    unknown.count = 1;
    unknown.stored_size = 0x7FFFFF00u;
    unknown.bytes = {1, 2, 3};
    c.blocks.push_back(unknown);
    c.write(path);
  } else if (name == "regular_grid_2gib") {
    regular_zeros().write(path);
  } else if (name == "rectilinear_2p29") {
    rectilinear_one_cell().write(path);
  } else if (name == "salvage_zeroed") {
    salvage_file(path);
  } else {
    throw std::invalid_argument("no hostile file called " + name);
  }
}

}  // namespace ivol::test::hostile
