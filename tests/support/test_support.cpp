#include "test_support.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "ivol/crc32c.hpp"

namespace ivol::test {
namespace {

struct TempDir {
  std::string path;
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "ivol-test-XXXXXX").string();
    path = mkdtemp(pattern.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

// All finite binary16 values, ascending, with their bit patterns: the
// rounding oracle for reference_encode.
struct HalfTable {
  std::vector<std::pair<double, std::uint16_t>> values;
  HalfTable() {
    for (std::uint32_t b = 0; b < 0x10000; ++b) {
      const auto bits = static_cast<std::uint16_t>(b);
      const unsigned exponent = (bits >> 10) & 0x1F;
      if (exponent == 31) continue;
      if (bits == 0x8000) continue;  // keep +0 only; the sign is handled apart
      values.emplace_back(reference_decode(ValueEncoding::Binary16, bits), bits);
    }
    std::sort(values.begin(), values.end());
  }
};

}  // namespace

std::string temp_dir() {
  static TempDir dir;
  return dir.path;
}

std::string temp_path(const std::string& name) { return temp_dir() + "/" + name; }

std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

std::vector<float> random_volume(const Dims& dims, std::mt19937_64& rng, double noise, int blobs) {
  std::vector<float> v(voxel_count(dims), 0.0f);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  struct Blob {
    double c[3], r;
    float value;
  };
  std::vector<Blob> list;
  for (int b = 0; b < blobs; ++b)
    list.push_back({{unit(rng) * dims[0], unit(rng) * dims[1], unit(rng) * dims[2]},
                    1.0 + unit(rng) * std::max({dims[0], dims[1], dims[2]}) / 3.0,
                    static_cast<float>(unit(rng) * 4.0)});
  std::normal_distribution<double> gauss(0.0, noise > 0 ? noise : 1.0);
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x) {
        float value = 0.25f;
        for (const Blob& b : list) {
          const double dx = x - b.c[0], dy = y - b.c[1], dz = z - b.c[2];
          if (dx * dx + dy * dy + dz * dz < b.r * b.r) value = b.value;
        }
        if (noise > 0 && value != 0.25f) value += static_cast<float>(gauss(rng));
        v[(std::uint64_t{z} * dims[1] + y) * dims[0] + x] = value;
      }
  return v;
}

double reference_decode(ValueEncoding encoding, std::uint32_t bits) {
  switch (encoding) {
    case ValueEncoding::Binary16: {
      const double sign = (bits & 0x8000) ? -1.0 : 1.0;
      const int exponent = static_cast<int>((bits >> 10) & 0x1F);
      const int mantissa = static_cast<int>(bits & 0x3FF);
      if (exponent == 0) return sign * std::ldexp(mantissa, -24);
      if (exponent == 31) return mantissa ? std::numeric_limits<double>::quiet_NaN() : sign * INFINITY;
      return sign * std::ldexp(1024 + mantissa, exponent - 25);
    }
    case ValueEncoding::UInt16:
      return bits & 0xFFFF;
    case ValueEncoding::Float32: {
      float f;
      std::memcpy(&f, &bits, 4);
      return f;
    }
  }
  return 0;
}

std::uint32_t reference_encode(ValueEncoding encoding, double value) {
  switch (encoding) {
    case ValueEncoding::Binary16: {
      static const HalfTable table;
      if (std::isnan(value)) return 0x7E00;
      const std::uint32_t sign = std::signbit(value) ? 0x8000 : 0;
      const double a = std::fabs(value);
      if (a >= 65520.0) return sign | 0x7C00;
      const auto& t = table.values;
      auto it = std::lower_bound(t.begin(), t.end(), std::make_pair(a, std::uint16_t{0}));
      if (it == t.end()) return sign | t.back().second;  // between 65504 and 65520
      if (it->first == a || it == t.begin()) return sign | it->second;
      const auto below = it - 1;
      const double up = it->first - a;
      const double down = a - below->first;
      std::uint16_t bits;
      if (up < down)
        bits = it->second;
      else if (down < up)
        bits = below->second;
      else
        bits = (it->second & 1) ? below->second : it->second;  // tie: even significand
      return sign | bits;
    }
    case ValueEncoding::UInt16: {
      const double r = std::nearbyint(value);
      return static_cast<std::uint32_t>(std::clamp(r, 0.0, 65535.0));
    }
    case ValueEncoding::Float32: {
      if (std::isnan(value)) return 0x7FC00000u;
      const float f = static_cast<float>(value);
      std::uint32_t bits;
      std::memcpy(&bits, &f, 4);
      return bits;
    }
  }
  return 0;
}

std::vector<std::uint32_t> reference_lod(const std::vector<std::uint32_t>& bits, const Dims& dims,
                                         ValueEncoding encoding, unsigned lod) {
  const Dims out_dims = lod_dims(dims, lod);
  const std::uint32_t side = 1u << lod;
  std::vector<std::uint32_t> out(voxel_count(out_dims));
  for (std::uint32_t k = 0; k < out_dims[2]; ++k)
    for (std::uint32_t j = 0; j < out_dims[1]; ++j)
      for (std::uint32_t i = 0; i < out_dims[0]; ++i) {
        long double sum = 0;
        std::uint64_t count = 0;
        for (std::uint32_t z = k * side; z < std::min(dims[2], (k + 1) * side); ++z)
          for (std::uint32_t y = j * side; y < std::min(dims[1], (j + 1) * side); ++y)
            for (std::uint32_t x = i * side; x < std::min(dims[0], (i + 1) * side); ++x) {
              sum += reference_decode(encoding, bits[(std::uint64_t{z} * dims[1] + y) * dims[0] + x]);
              ++count;
            }
        out[(std::uint64_t{k} * out_dims[1] + j) * out_dims[0] + i] =
            reference_encode(encoding, static_cast<double>(sum / count));
      }
  return out;
}

std::uint64_t ulp_distance(ValueEncoding encoding, std::uint32_t a, std::uint32_t b) {
  if (a == b) return 0;
  if (encoding == ValueEncoding::UInt16) return a > b ? a - b : b - a;
  // Map sign-magnitude bit patterns onto a monotonic integer line.
  const unsigned top = encoding == ValueEncoding::Binary16 ? 15 : 31;
  auto line = [top](std::uint32_t v) -> std::int64_t {
    const std::int64_t magnitude = v & ((1u << top) - 1);
    return (v >> top) & 1u ? -magnitude : magnitude;
  };
  const std::int64_t d = line(a) - line(b);
  return static_cast<std::uint64_t>(d < 0 ? -d : d);
}

CommandResult run_command(const std::string& command) {
  CommandResult result;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return result;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) result.output.append(buffer, n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

void refresh_container_checksums(std::vector<std::uint8_t>& f) {
  auto u32 = [&](std::size_t at) {
    std::uint32_t v;
    std::memcpy(&v, &f[at], 4);
    return v;
  };
  auto u64 = [&](std::size_t at) {
    std::uint64_t v;
    std::memcpy(&v, &f[at], 8);
    return v;
  };
  auto put32 = [&](std::size_t at, std::uint32_t v) { std::memcpy(&f[at], &v, 4); };
  const std::uint32_t header_size = u32(12);
  put32(header_size - 4, crc32c(f.data(), header_size - 4));
  const std::size_t footer = f.size() - 32;
  const std::uint64_t index_offset = u64(footer);
  const std::uint64_t index_size = u64(footer + 8);
  if (index_offset + index_size <= f.size()) put32(footer + 16, crc32c(&f[index_offset], index_size));
  put32(footer + 20, crc32c(&f[footer], 20));
}

}  // namespace ivol::test
