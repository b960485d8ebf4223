#include "ivol/recon/preview.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>

#include "ivol/keep_mask.hpp"

namespace ivol::recon {
namespace {

bool is_power_of_two(unsigned n) { return n != 0 && (n & (n - 1)) == 0; }

// `full` coarsened `factor` times: each voxel covers factor³ full voxels,
// centred on them.
VolumeGrid coarsened(const VolumeGrid& full, unsigned factor) {
  VolumeGrid coarse;
  for (int a = 0; a < 3; ++a) {
    coarse.size[a] = (full.size[a] + factor - 1) / factor;
    coarse.voxel_size[a] = full.voxel_size[a] * factor;
    coarse.origin[a] = full.origin[a] + 0.5 * (factor - 1) * full.voxel_size[a];
  }
  return coarse;
}

// FDK of `grid` from every `thinning`-th view with thinning² pixels merged
// (fewer where the scan is small); each z-slice goes to `slice` in order, on
// rank 0 only when distributed.
void reconstruct_thinned(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                         const VolumeGrid& grid, unsigned thinning,
                         const std::function<void(std::uint32_t k, const float* values)>& slice) {
  // Keep at least a few pixels and views when the scan is small.
  unsigned bin = thinning;
  while (bin > 1 && (geometry.detector.columns / static_cast<int>(bin) < 16 ||
                     geometry.detector.rows / static_cast<int>(bin) < 16))
    bin /= 2;
  unsigned view_step = thinning;
  while (view_step > 1 && geometry.view_count() / view_step < 32) view_step /= 2;
  ReducedProjections reduced(projections, view_step, bin);
  const ScanGeometry reduced_geometry = reduce_scan(geometry, view_step, bin);
  FdkReconstructor reconstructor(reduced, reduced_geometry, options);
  const std::size_t area = std::size_t{grid.size[0]} * grid.size[1];
  reconstructor.reconstruct(grid, [&](std::uint32_t k0, std::uint32_t k1, const float* data) {
    for (std::uint32_t k = k0; k < k1; ++k) slice(k, data + (k - k0) * area);
  });
}

// Distributed, only rank 0 received the preview; every rank needs it to
// generate the same structure.
void share(const FdkOptions& options, std::vector<float>& values) {
  if (options.exchange && options.exchange->size() > 1) options.exchange->broadcast(values);
}

// Largest value within `reach` places along one axis of a line of `n`
// values `stride` apart, every `ratio`-th place kept: out[c] = max of in over
// [ratio·c − reach, ratio·c + ratio − 1 + reach].
void pool_line(const float* in, std::size_t n, std::size_t stride, unsigned ratio, unsigned reach, float* out,
               std::size_t out_n, std::size_t out_stride) {
  for (std::size_t c = 0; c < out_n; ++c) {
    const std::size_t lo = ratio * c >= reach ? ratio * c - reach : 0;
    const std::size_t hi = std::min(n, ratio * c + ratio + reach);
    float best = -std::numeric_limits<float>::infinity();
    for (std::size_t s = lo; s < hi; ++s) best = std::max(best, in[s * stride]);
    out[c * out_stride] = best;
  }
}

void check_factor(unsigned factor, unsigned smallest) {
  if (factor < smallest || !is_power_of_two(factor))
    throw std::invalid_argument("preview: the factor must be a power of two, at least " + std::to_string(smallest));
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Finished layers of cells until the threshold is known: in host memory
// while the budget lasts, the rest in an unlinked temporary file.
class CellLayers {
 public:
  CellLayers(std::size_t area, std::uint64_t budget, std::string directory)
      : area_(area), budget_(budget), directory_(std::move(directory)) {
    if (directory_.empty()) {
      const char* tmpdir = std::getenv("TMPDIR");
      directory_ = tmpdir != nullptr && *tmpdir != '\0' ? tmpdir : "/tmp";
    }
  }
  CellLayers(const CellLayers&) = delete;
  CellLayers& operator=(const CellLayers&) = delete;
  ~CellLayers() {
    if (fd_ >= 0) ::close(fd_);
  }

  void put(std::size_t layer, const float* values) {
    if (layer < held_.size() || (held_.size() == layer && (layer + 1) * bytes() <= budget_)) {
      held_.resize(std::max(held_.size(), layer + 1));
      held_[layer].assign(values, values + area_);
      return;
    }
    if (fd_ < 0) open_file();
    transfer(true, layer, const_cast<float*>(values));
    spilled_ += bytes();
  }
  void get(std::size_t layer, float* values) {
    if (layer < held_.size()) {
      std::copy(held_[layer].begin(), held_[layer].end(), values);
      return;
    }
    transfer(false, layer, values);
  }
  std::uint64_t held_bytes() const { return held_.size() * bytes(); }
  std::uint64_t spilled_bytes() const { return spilled_; }

 private:
  std::uint64_t bytes() const { return area_ * sizeof(float); }
  void open_file() {
    fd_ = ::open(directory_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (fd_ >= 0) return;
    std::string name = directory_ + "/ivol-preview-XXXXXX";
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0)
      throw std::runtime_error("detection preview: the preview exceeds its memory budget of " +
                               std::to_string(budget_) + " bytes and no temporary file can be made in '" + directory_ +
                               "': " + std::strerror(errno));
    ::unlink(name.c_str());
  }
  // Layers past those held lie one after another from the file's start.
  void transfer(bool write, std::size_t layer, float* values) {
    auto* at = reinterpret_cast<char*>(values);
    std::uint64_t left = bytes();
    auto offset = static_cast<off_t>((layer - held_.size()) * bytes());
    while (left > 0) {
      const ssize_t n = write ? ::pwrite(fd_, at, left, offset) : ::pread(fd_, at, left, offset);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0)
        throw std::runtime_error("detection preview: " + std::string(write ? "writing" : "reading") +
                                 " the temporary file in '" + directory_ +
                                 "' failed: " + (n < 0 ? std::strerror(errno) : "end of file"));
      at += n, left -= static_cast<std::uint64_t>(n), offset += n;
    }
  }

  std::size_t area_;
  std::uint64_t budget_;
  std::string directory_;
  std::vector<std::vector<float>> held_;
  int fd_ = -1;
  std::uint64_t spilled_ = 0;
};

}  // namespace

Preview reconstruct_preview(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                            const VolumeGrid& full, unsigned factor) {
  check_factor(factor, 2);
  const auto start = std::chrono::steady_clock::now();
  Preview preview;
  preview.grid = coarsened(full, factor);
  preview.values.resize(preview.grid.voxel_count());
  const std::size_t area = std::size_t{preview.grid.size[0]} * preview.grid.size[1];
  reconstruct_thinned(projections, geometry, options, preview.grid, std::max(1U, factor / 2),
                      [&](std::uint32_t k, const float* values) {
                        std::copy(values, values + area,
                                  preview.values.begin() + static_cast<std::ptrdiff_t>(k * area));
                      });
  share(options, preview.values);
  preview.otsu_threshold = otsu_threshold(preview.values.data(), preview.values.size());
  preview.seconds = seconds_since(start);
  return preview;
}

Preview reconstruct_detection_preview(ProjectionSource& projections, const ScanGeometry& geometry,
                                      const FdkOptions& options, const VolumeGrid& full, unsigned factor,
                                      unsigned thinning, unsigned margin_voxels) {
  check_factor(factor, 2);
  if (thinning == 0 || !is_power_of_two(thinning))
    throw std::invalid_argument("detection preview: the thinning must be a power of two");
  const auto start = std::chrono::steady_clock::now();
  const unsigned ratio = factor > 2 ? 2 : 1;  // samples per cell and axis
  const unsigned spacing = factor / ratio;
  const unsigned reach = (margin_voxels + spacing - 1) / spacing;
  const VolumeGrid samples = coarsened(full, spacing);
  Preview preview;
  preview.grid = coarsened(full, factor);
  const std::size_t sx = samples.size[0], sy = samples.size[1], sz = samples.size[2];
  const std::size_t cx = preview.grid.size[0], cy = preview.grid.size[1], cz = preview.grid.size[2];
  // Slices of samples pooled along x and y as they arrive (a quarter of
  // each), so that the samples themselves are never all held; one sample in
  // eight is kept for Otsu's threshold.
  std::vector<float> pooled_xy(cx * cy * sz, -std::numeric_limits<float>::infinity());
  std::vector<float> otsu_samples;
  otsu_samples.reserve(((sx + 1) / 2) * ((sy + 1) / 2) * ((sz + 1) / 2));
  std::vector<float> along_x(cx * sy);
  reconstruct_thinned(projections, geometry, options, samples, thinning, [&](std::uint32_t k, const float* values) {
    for (std::size_t j = 0; j < sy; ++j) pool_line(values + j * sx, sx, 1, ratio, reach, &along_x[j * cx], cx, 1);
    for (std::size_t i = 0; i < cx; ++i)
      pool_line(&along_x[i], sy, cx, ratio, reach, &pooled_xy[k * cx * cy + i], cy, cx);
    if (k % 2 == 0)
      for (std::size_t j = 0; j < sy; j += 2)
        for (std::size_t i = 0; i < sx; i += 2) otsu_samples.push_back(values[j * sx + i]);
  });
  share(options, pooled_xy);
  share(options, otsu_samples);
  preview.values.resize(cx * cy * cz);
  for (std::size_t j = 0; j < cy; ++j)
    for (std::size_t i = 0; i < cx; ++i)
      pool_line(&pooled_xy[j * cx + i], sz, cx * cy, ratio, reach, &preview.values[j * cx + i], cz, cx * cy);
  // Otsu's threshold of the samples, not of the maxima: the samples are a
  // reconstruction of the object, whose histogram the maxima would bias.
  preview.otsu_threshold = otsu_threshold(otsu_samples.data(), otsu_samples.size());
  preview.seconds = seconds_since(start);
  return preview;
}

DetectionMask detect_need_mask(ProjectionSource& projections, const ScanGeometry& geometry, const FdkOptions& options,
                               const VolumeGrid& full, const DetectionMaskOptions& detection) {
  const DetectionRule& rule = detection.rule;
  check_factor(rule.factor, 2);
  if (rule.thinning == 0 || !is_power_of_two(rule.thinning))
    throw std::invalid_argument("detection preview: the thinning must be a power of two");
  const auto start = std::chrono::steady_clock::now();
  // The same samples and pooling as reconstruct_detection_preview.
  const unsigned ratio = rule.factor > 2 ? 2 : 1;
  const unsigned spacing = rule.factor / ratio;
  const unsigned reach = (detection.margin_voxels + spacing - 1) / spacing;
  const VolumeGrid samples = coarsened(full, spacing);
  DetectionMask result;
  result.grid = coarsened(full, rule.factor);
  const std::size_t sx = samples.size[0], sy = samples.size[1], sz = samples.size[2];
  const std::size_t cx = result.grid.size[0], cy = result.grid.size[1], cz = result.grid.size[2];
  const std::size_t area = cx * cy;
  // Slices pooled along x and y, in a ring: cell layer c takes the slices
  // [ratio·c − reach, ratio·c + ratio + reach), at most ratio + 2·reach.
  const std::size_t ring_layers = ratio + 2 * reach + 1;
  std::vector<float> ring(ring_layers * area);
  std::vector<float> along_x(cx * sy);
  std::vector<float> cells(area);
  std::vector<float> otsu_samples;
  otsu_samples.reserve(((sx + 1) / 2) * ((sy + 1) / 2) * ((sz + 1) / 2));
  // The budget covers everything the preview holds; the cell layers take
  // what the ring, the samples for Otsu and the need mask (a byte per cell)
  // leave of it.
  const std::uint64_t fixed_bytes =
      (ring.size() + along_x.size() + cells.size() + otsu_samples.capacity()) * sizeof(float) + area * cz;
  CellLayers layers(area, detection.preview_memory > fixed_bytes ? detection.preview_memory - fixed_bytes : 0,
                    detection.temp_directory);
  std::size_t next_layer = 0;
  auto finish_layers_through = [&](std::size_t k) {
    for (; next_layer < cz; ++next_layer) {
      const std::size_t c = next_layer;
      const std::size_t lo = ratio * c >= reach ? ratio * c - reach : 0;
      const std::size_t hi = std::min(sz, ratio * c + ratio + reach);
      if (hi - 1 > k) return;
      std::fill(cells.begin(), cells.end(), -std::numeric_limits<float>::infinity());
      for (std::size_t z = lo; z < hi; ++z) {
        const float* pooled = &ring[(z % ring_layers) * area];
        for (std::size_t i = 0; i < area; ++i) cells[i] = std::max(cells[i], pooled[i]);
      }
      layers.put(c, cells.data());
    }
  };
  reconstruct_thinned(projections, geometry, options, samples, rule.thinning,
                      [&](std::uint32_t k, const float* values) {
                        for (std::size_t j = 0; j < sy; ++j)
                          pool_line(values + j * sx, sx, 1, ratio, reach, &along_x[j * cx], cx, 1);
                        float* pooled = &ring[(k % ring_layers) * area];
                        for (std::size_t i = 0; i < cx; ++i)
                          pool_line(&along_x[i], sy, cx, ratio, reach, pooled + i, cy, cx);
                        if (k % 2 == 0)
                          for (std::size_t j = 0; j < sy; j += 2)
                            for (std::size_t i = 0; i < sx; i += 2) otsu_samples.push_back(values[j * sx + i]);
                        finish_layers_through(k);
                      });
  const bool distributed = options.exchange && options.exchange->size() > 1;
  const bool producer = !distributed || options.exchange->rank() == 0;
  if (producer && next_layer != cz) throw std::logic_error("detection preview: not every cell layer was pooled");
  share(options, otsu_samples);
  result.otsu_threshold = otsu_threshold(otsu_samples.data(), otsu_samples.size());
  result.threshold =
      detection.threshold ? *detection.threshold : static_cast<float>(rule.otsu_share * result.otsu_threshold);
  result.peak_preview_bytes = fixed_bytes + layers.held_bytes();
  result.spilled_bytes = layers.spilled_bytes();
  std::vector<float>().swap(otsu_samples);
  // The second pass: each layer of cells against the threshold, as
  // threshold_keep_mask with no margin (the margin was applied in pooling).
  const Dims full_dims{full.size[0], full.size[1], full.size[2]};
  result.mask.dims = full_dims;
  result.mask.factor = rule.factor;
  result.mask.cells = Dims{result.grid.size[0], result.grid.size[1], result.grid.size[2]};
  result.mask.need.assign(area * cz, 0);
  for (std::size_t c = 0; c < cz; ++c) {
    if (producer) layers.get(c, cells.data());
    share(options, cells);
    std::uint8_t* need = &result.mask.need[c * area];
    for (std::size_t i = 0; i < area; ++i) need[i] = cells[i] > result.threshold ? 1 : 0;
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace ivol::recon
