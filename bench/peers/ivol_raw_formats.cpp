// ivol's own forms (octree, regular grid) and raw files, for peers_bench.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "ivol/binary16.hpp"
#include "ivol/bricked_writer.hpp"
#include "ivol/build.hpp"
#include "ivol/reader.hpp"
#include "ivol/structures.hpp"
#include "ivol/writer.hpp"
#include "peer_format.hpp"

namespace peers {

std::vector<float> PeerFormat::read_preview(const std::string& path, std::uint32_t n, std::uint32_t factor) {
  return downsample(read_box(path, n, ivol::Box{{0, 0, 0}, {n, n, n}}), n, factor);
}

std::vector<float> downsample(const std::vector<float>& volume, std::uint32_t n, std::uint32_t factor) {
  const std::uint32_t m = n / factor;
  std::vector<double> sums(std::uint64_t{m} * m * m, 0.0);
  for (std::uint32_t z = 0; z < n; ++z)
    for (std::uint32_t y = 0; y < n; ++y) {
      const float* row = volume.data() + (std::uint64_t{z} * n + y) * n;
      double* out = sums.data() + (std::uint64_t{z / factor} * m + y / factor) * m;
      for (std::uint32_t x = 0; x < n; ++x) out[x / factor] += row[x];
    }
  std::vector<float> result(sums.size());
  const double scale = 1.0 / (double(factor) * factor * factor);
  for (std::size_t i = 0; i < sums.size(); ++i) result[i] = static_cast<float>(sums[i] * scale);
  return result;
}

std::uint64_t bytes_read_by_process() {
  std::ifstream io("/proc/self/io");
  std::string key;
  std::uint64_t value = 0;
  while (io >> key >> value)
    if (key == "rchar:") return value;
  throw std::runtime_error("/proc/self/io has no rchar");
}

std::uint64_t bytes_on_disk(const std::string& path) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(path)) return fs::file_size(path);
  std::uint64_t total = 0;
  for (const auto& entry : fs::directory_iterator(path))
    if (entry.is_regular_file()) total += entry.file_size();
  return total;
}

namespace {

std::vector<std::string> files_of(const std::string& path) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(path)) return {path};
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(path))
    if (entry.is_regular_file()) files.push_back(entry.path().string());
  return files;
}

}  // namespace

void flush_and_evict(const std::string& path) {
  for (const std::string& file : files_of(path)) {
    const int fd = ::open(file.c_str(), O_RDONLY);
    if (fd < 0) throw std::runtime_error("cannot open " + file);
    ::fdatasync(fd);  // dirty pages cannot be dropped
    ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
    ::close(fd);
  }
}

std::uint64_t bytes_in_page_cache(const std::string& path) {
  const long page = ::sysconf(_SC_PAGESIZE);
  std::uint64_t total = 0;
  for (const std::string& file : files_of(path)) {
    const std::uint64_t size = std::filesystem::file_size(file);
    if (size == 0) continue;
    const int fd = ::open(file.c_str(), O_RDONLY);
    if (fd < 0) throw std::runtime_error("cannot open " + file);
    void* map = ::mmap(nullptr, size, PROT_READ, MAP_SHARED, fd, 0);
    ::close(fd);
    if (map == MAP_FAILED) throw std::runtime_error("cannot map " + file);
    std::vector<unsigned char> resident((size + page - 1) / page);
    if (::mincore(map, size, resident.data()) != 0) throw std::runtime_error("mincore failed on " + file);
    ::munmap(map, size);
    for (std::size_t i = 0; i < resident.size(); ++i)
      if (resident[i] & 1) total += std::min<std::uint64_t>(page, size - i * std::uint64_t(page));
  }
  return total;
}

namespace {

std::vector<std::uint8_t> to_binary16_bytes(const std::vector<float>& values) {
  std::vector<std::uint8_t> bytes(values.size() * 2);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::uint16_t bits = ivol::float_to_binary16(values[i]);
    bytes[2 * i] = static_cast<std::uint8_t>(bits & 0xff);
    bytes[2 * i + 1] = static_cast<std::uint8_t>(bits >> 8);
  }
  return bytes;
}

// What both ivol forms read the same way: through a Reader, a preview from
// the level of detail (stored inner averages for the octree; computed from
// the dense export for the regular grid, spec §12.3).
class IvolFile : public PeerFormat {
 public:
  std::vector<float> read_box(const std::string& path, std::uint32_t, const ivol::Box& box) override {
    ivol::Reader reader(path);
    return reader.read_box(box);
  }
  std::vector<float> read_preview(const std::string& path, std::uint32_t, std::uint32_t factor) override {
    ivol::Reader reader(path);
    unsigned lod = 0;
    while ((1u << lod) < factor) ++lod;
    return reader.read_lod(lod);
  }
};

// The octree: built from the dense volume (with the keep mask: full
// resolution where it is set, one mean-valued leaf elsewhere) and written
// with the library's defaults (16 KiB blocks, zstd level 3, all cores).
class IvolOctree : public IvolFile {
 public:
  explicit IvolOctree(bool keep_mode) : keep_mode_(keep_mode) {}
  std::string name() const override { return "ivol octree"; }
  std::string details() const override {
    return keep_mode_ ? "binary16; full resolution = kept voxels, the rest in mean-valued leaves; zstd-3, 16 KiB blocks"
                      : "binary16, every voxel a leaf; zstd-3, 16 KiB blocks";
  }
  void write(const VolumeCase& volume, const std::string& path) override {
    ivol::BuildOptions options;
    if (volume.keep) options.keep_mask = volume.keep->data();
    const ivol::BuildResult built = ivol::build_octree(volume.values->data(), {volume.n, volume.n, volume.n}, options);
    ivol::write_octree(built.octree, ivol::Metadata{}, path);
  }

 private:
  bool keep_mode_;
};

// The paper's regular grid in its form of spec §8A: every voxel, binary16.
class IvolRegular : public IvolFile {
 public:
  std::string name() const override { return "ivol regular"; }
  std::string details() const override { return "binary16, every voxel; zstd-3, 16 KiB blocks"; }
  void write(const VolumeCase& volume, const std::string& path) override {
    ivol::NeedMask everything;
    everything.dims = {volume.n, volume.n, volume.n};
    everything.factor = 1;
    everything.cells = everything.dims;
    everything.need.assign(volume.voxel_count(), 1);
    auto structure = ivol::generate_structure(ivol::StructureKind::Regular, everything);
    structure->sample_dense(volume.values->data());
    ivol::write_structure(*structure, path, ivol::Metadata{});
  }
};

// The bricked regular grid (spec §8A.4): every voxel, binary16, bricks of
// 32^3 each predicted in 3-D (codec 3, or codec 2 where that is smaller), as
// `ivol convert` writes lossless every-voxel files since issue 22.
class IvolBricked : public IvolFile {
 public:
  std::string name() const override { return "ivol bricked"; }
  std::string details() const override {
    return "binary16, every voxel; 32^3 bricks, codec 3 (3-D prediction, zstd-3 over residual byte planes)";
  }
  void write(const VolumeCase& volume, const std::string& path) override {
    const ivol::Dims dims{volume.n, volume.n, volume.n};
    ivol::BrickedOptions options;
    options.encoding = ivol::ValueEncoding::Binary16;
    ivol::BrickedGridWriter writer(path, dims, options);
    const std::size_t slice = std::size_t{volume.n} * volume.n;
    std::vector<std::uint16_t> layer;
    while (writer.next_layer_count() > 0) {
      const float* first = volume.values->data() + writer.next_layer_first() * slice;
      layer.resize(writer.next_layer_count() * slice);
      for (std::size_t i = 0; i < layer.size(); ++i) layer[i] = ivol::float_to_binary16(first[i]);
      writer.add_layer(layer.data());
    }
    writer.finish(ivol::Metadata{});
  }
};

// A raw file, x fastest; a box is read row by row with pread, as a user of a
// raw file would (only the bytes of the box are asked for).
class RawFile : public PeerFormat {
 public:
  explicit RawFile(bool half) : half_(half) {}
  std::string name() const override { return half_ ? "raw binary16" : "raw float32"; }
  std::string details() const override {
    return half_ ? "every voxel, binary16, uncompressed" : "every voxel, float32 (the reference), uncompressed";
  }
  void write(const VolumeCase& volume, const std::string& path) override {
    std::FILE* file = std::fopen(path.c_str(), "wb");
    if (!file) throw std::runtime_error("cannot write " + path);
    if (half_) {
      const std::vector<std::uint8_t> bytes = to_binary16_bytes(*volume.values);
      std::fwrite(bytes.data(), 1, bytes.size(), file);
    } else {
      std::fwrite(volume.values->data(), sizeof(float), volume.values->size(), file);
    }
    if (std::fclose(file) != 0) throw std::runtime_error("cannot write " + path);
  }
  std::vector<float> read_box(const std::string& path, std::uint32_t n, const ivol::Box& box) override {
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0) throw std::runtime_error("cannot open " + path);
    const std::uint32_t width = box.hi[0] - box.lo[0];
    const std::size_t sample = half_ ? 2 : 4;
    std::vector<float> out(box.voxel_count());
    std::vector<std::uint8_t> row(width * sample);
    float* next = out.data();
    for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
      for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y) {
        const off_t offset = static_cast<off_t>(((std::uint64_t{z} * n + y) * n + box.lo[0]) * sample);
        if (::pread(fd, row.data(), row.size(), offset) != static_cast<ssize_t>(row.size())) {
          ::close(fd);
          throw std::runtime_error("short read from " + path);
        }
        if (half_) {
          for (std::uint32_t x = 0; x < width; ++x)
            *next++ = ivol::binary16_to_float(static_cast<std::uint16_t>(row[2 * x] | (row[2 * x + 1] << 8)));
        } else {
          std::memcpy(next, row.data(), row.size());
          next += width;
        }
      }
    ::close(fd);
    return out;
  }

 private:
  bool half_;
};

}  // namespace

std::vector<std::unique_ptr<PeerFormat>> ivol_formats(bool keep_mode) {
  std::vector<std::unique_ptr<PeerFormat>> formats;
  formats.push_back(std::make_unique<IvolOctree>(keep_mode));
  if (!keep_mode) formats.push_back(std::make_unique<IvolRegular>());
  if (!keep_mode) formats.push_back(std::make_unique<IvolBricked>());
  return formats;
}

std::vector<std::unique_ptr<PeerFormat>> raw_formats() {
  std::vector<std::unique_ptr<PeerFormat>> formats;
  formats.push_back(std::make_unique<RawFile>(true));
  formats.push_back(std::make_unique<RawFile>(false));
  return formats;
}

}  // namespace peers
