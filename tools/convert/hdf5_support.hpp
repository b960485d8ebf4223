// What the HDF5 readers and writers share: an owner for HDF5 identifiers,
// silence for HDF5's own error printing, and the reason HDF5 gives for a
// failure. Internal to tools/convert.
#pragma once

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <utility>

namespace ivol::convert::hdf5 {

// Owns an HDF5 identifier and closes it with the matching H5?close.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() { reset(); }
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, -1)), close_(other.close_) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      reset();
      id_ = std::exchange(other.id_, -1);
      close_ = other.close_;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  // Gives up ownership, for a close whose result must be checked.
  hid_t release() { return std::exchange(id_, -1); }
  void reset() {
    if (id_ >= 0 && close_) close_(id_);
    id_ = -1;
  }

 private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

// HDF5 prints its whole error stack to stderr by default; we throw our own
// messages instead, so silence it for the duration of a call.
class QuietErrors {
 public:
  QuietErrors() {
    H5Eget_auto2(H5E_DEFAULT, &old_function_, &old_data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietErrors() { H5Eset_auto2(H5E_DEFAULT, old_function_, old_data_); }
  QuietErrors(const QuietErrors&) = delete;
  QuietErrors& operator=(const QuietErrors&) = delete;

 private:
  H5E_auto2_t old_function_ = nullptr;
  void* old_data_ = nullptr;
};

// Projections are read one view at a time, and volumes a slab of slices at
// a time. A chunk that spans several views (slices) would be read and
// inflated again for every read unless HDF5's chunk cache (1 MiB by default)
// holds it; so the cache is sized to hold the chunks one image (the last two
// axes) touches, up to kMostChunkCache. Larger chunks are still read, at that
// cost. Returns a dataset access property list for H5Dopen2.
// The preemption weight stays HDF5's default, 0.75: at 1.0, libhdf5 1.10
// evicts only chunks read whole until its first pass has walked the whole
// list, and then stops, so chunks read in part (deeper than the slices a
// read takes, or taller than its band of rows) were never evicted and the
// cache grew past its size to every chunk of an image (30 MB under a 3 MiB
// cache: bands of rows then failed in the child's memory limit, by chunk
// shape rather than by size).
constexpr double kChunkPreemption = 0.75;
constexpr std::size_t kMostChunkCache = std::size_t{256} << 20;

inline Handle access_caching_one_image(hid_t file, const char* name, std::size_t most = kMostChunkCache) {
  Handle access(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
  Handle probe(H5Dopen2(file, name, H5P_DEFAULT), H5Dclose);
  if (!probe.valid()) return access;
  Handle create(H5Dget_create_plist(probe.get()), H5Pclose);
  Handle type(H5Dget_type(probe.get()), H5Tclose);
  Handle space(H5Dget_space(probe.get()), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (H5Pget_layout(create.get()) != H5D_CHUNKED || rank < 2 || rank > 8) return access;
  hsize_t chunk[8] = {}, shape[8] = {};
  if (H5Pget_chunk(create.get(), rank, chunk) != rank) return access;
  H5Sget_simple_extent_dims(space.get(), shape, nullptr);
  double bytes = static_cast<double>(H5Tget_size(type.get()));
  for (int a = 0; a < rank; ++a) bytes *= static_cast<double>(chunk[a]);
  for (int a = rank - 2; a < rank; ++a)
    if (chunk[a] > 0) bytes *= std::ceil(static_cast<double>(shape[a]) / static_cast<double>(chunk[a]));
  const double cache = std::clamp(bytes, double{1 << 20},
                                  std::max(double{1 << 20}, static_cast<double>(std::min(most, kMostChunkCache))));
  H5Pset_chunk_cache(access.get(), 12421, static_cast<std::size_t>(cache), kChunkPreemption);
  return access;
}

// Whether the failure on HDF5's error stack is a refused allocation (the
// library's "memory allocation failed"), which is a limit, not a damaged
// file.
inline bool out_of_memory() {
  bool found = false;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned, const H5E_error2_t* error, void* out) -> herr_t {
        if (error->maj_num == H5E_RESOURCE && (error->min_num == H5E_NOSPACE || error->min_num == H5E_CANTALLOC))
          *static_cast<bool*>(out) = true;
        return 0;
      },
      &found);
  return found;
}

// The most specific description on HDF5's error stack, to explain a failure.
inline std::string reason() {
  std::string text;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned depth, const H5E_error2_t* error, void* out) -> herr_t {
        if (depth == 0 && error->desc) *static_cast<std::string*>(out) = error->desc;
        return 0;
      },
      &text);
  return text.empty() ? std::string() : " (HDF5: " + text + ")";
}

}  // namespace ivol::convert::hdf5
