#include "ivol/reader.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "box_output.hpp"
#include "brick_grid.hpp"
#include "grid_copy.hpp"
#include "ivol/error.hpp"
#include "layout.hpp"
#include "reader_impl.hpp"
#include "tree_walk.hpp"
#include "whole_level.hpp"

namespace ivol {

namespace {

// A request's output: `per_voxel` elements of T for each voxel of `box`. A
// box of a valid file may hold 2^62 voxels (a slice of 2^31 a side) or
// more; what cannot be allocated is LimitExceeded naming the box and the
// bytes, not std::bad_alloc or std::length_error.
template <typename T>
std::vector<T> output_for(const Box& box, std::size_t per_voxel = 1) {
  const std::uint64_t voxels = box.voxel_count();
  std::uint64_t count = 0, bytes = 0;
  const bool wraps =
      __builtin_mul_overflow(voxels, per_voxel, &count) || __builtin_mul_overflow(count, sizeof(T), &bytes);
  const std::string what = "the output for the box " + box.to_string() + " (" + std::to_string(voxels) + " voxels";
  try {
    if (wraps) throw std::length_error("");
    if (count > std::vector<T>().max_size()) throw std::length_error("");
    return std::vector<T>(count);
  } catch (const std::bad_alloc&) {
  } catch (const std::length_error&) {
  }
  throw Error(ErrorClass::LimitExceeded,
              what +
                  (wraps ? ", more than 2^64 bytes" : ", " + std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB") +
                  ") cannot be allocated: ask for a smaller box or a coarser level");
}

// Physical values of all 65536 codes of a 16-bit encoding: cheaper than
// decoding each voxel when a box is large.
std::vector<float> physical_table(const VolumeLayout& v) {
  std::vector<float> table(65536);
  for (std::uint32_t code = 0; code < 65536; ++code)
    table[code] = static_cast<float>(v.physical(decode_value(v.encoding, code)));
  return table;
}

// Stored bits of every voxel of `box` at level of detail `lod` for the grid
// structures of spec §8A: the cells' values at full resolution, and the mean
// of §12.3 (binary64, z then y then x) at coarser levels.
// With `salvage`, a cell whose value cannot be read takes the stored code 0
// (a grid has no coarser level to fall back on) and is logged.
// Stored bits of `box` at level of detail `lod` from the level the file
// stores (a bricked grid, spec §8A.5): the same bits as summing the
// full-resolution voxels under it, without reading them.
std::vector<std::uint32_t> stored_level_bits(Reader::Impl& impl, const Box& box, unsigned lod) {
  const VolumeLayout& v = impl.info.layout;
  const detail::BrickGrid level(lod_dims(v.dims, lod), v.cell_log2);
  const auto slot = static_cast<std::uint8_t>(Reader::Impl::kStoredLevelSlot + lod);
  impl.plan_box(box, lod);
  std::vector<std::uint32_t> bits = output_for<std::uint32_t>(box);
  const bool wide = encoding_width(v.encoding) == 4;
  std::size_t n = 0;
  for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
    for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
      for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x) {
        const std::uint8_t* p = impl.element(slot, level.value_index(x, y, z));
        bits[n++] = wide ? layout::load<std::uint32_t>(p) : std::uint32_t{layout::load<std::uint16_t>(p)};
      }
  return bits;
}

std::vector<std::uint32_t> grid_bits(Reader::Impl& impl, const Box& box, unsigned lod,
                                     detail::SalvageLog* salvage = nullptr) {
  const VolumeLayout& v = impl.info.layout;
  const detail::GridStructure& grid = *impl.grid;
  if (lod > 0 && !salvage && impl.stored_level(lod)) return stored_level_bits(impl, box, lod);
  if (lod == 0) {
    std::vector<std::uint32_t> bits = output_for<std::uint32_t>(box);
    grid.for_each_cell(box, [&](const Box& region, std::uint64_t index) {
      std::uint32_t value = 0;
      if (!salvage) {
        value = impl.value_bits(index);
      } else if (const Error* known = impl.known_failure(3, index)) {
        salvage->add(region, 0, known->what());
      } else {
        try {
          value = impl.value_bits(index);
        } catch (const Error& e) {
          salvage->add(region, 0, e.what());
        }
      }
      detail::fill_region(bits.data(), box, region, value);
    });
    return bits;
  }
  // A level of detail accumulates the sums of one layer of output cells at a
  // time, from runs of equal voxels along x: memory in proportion to the
  // output, never to the full-resolution region under it. Each cell's sum
  // still takes its voxels one by one in the order z, then y, then x, so the
  // result is bit for bit the sequential sum of spec §12.3.
  __extension__ typedef unsigned __int128 u128;
  u128 under = 1;  // full-resolution voxels under the box
  for (int a = 0; a < 3; ++a)
    under *= std::min<std::uint64_t>(std::uint64_t{box.hi[a]} << lod, v.dims[a]) - (std::uint64_t{box.lo[a]} << lod);
  if (under > impl.grid_lod_voxels)
    throw Error(ErrorClass::LimitExceeded,
                impl.file.path() + ": level of detail " + std::to_string(lod) + " of " + box.to_string() +
                    " sums the grid's full-resolution voxels under it, more than this reader's limit of " +
                    std::to_string(impl.grid_lod_voxels) + " (ReaderOptions::grid_lod_voxels)");
  if (salvage) {
    // A salvaged grid: the full-resolution region is read once (within the
    // limit above), so that each cell that did not survive is met and listed
    // once; it reads as the stored code 0.
    Box full;
    for (int a = 0; a < 3; ++a) {
      full.lo[a] = box.lo[a] << lod;
      full.hi[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(std::uint64_t{box.hi[a]} << lod, v.dims[a]));
    }
    std::vector<DamagedRegion> fine_damage;
    detail::SalvageLog fine_log{fine_damage};
    const std::vector<std::uint32_t> fine = grid_bits(impl, full, 0, salvage ? &fine_log : nullptr);
    fine_log.flush();
    for (const DamagedRegion& d : fine_damage) {  // into the coordinates of the level of detail
      Box coarse;
      for (int a = 0; a < 3; ++a) {
        coarse.lo[a] = d.region.lo[a] >> lod;
        coarse.hi[a] = static_cast<std::uint32_t>((std::uint64_t{d.region.hi[a]} + (1ull << lod) - 1) >> lod);
      }
      salvage->add(coarse, 0, d.message);
    }
    const std::uint64_t fx = full.hi[0] - full.lo[0], fy = full.hi[1] - full.lo[1];
    std::vector<std::uint32_t> bits = output_for<std::uint32_t>(box);
    std::size_t n = 0;
    for (std::uint32_t k = box.lo[2]; k < box.hi[2]; ++k)
      for (std::uint32_t j = box.lo[1]; j < box.hi[1]; ++j)
        for (std::uint32_t i = box.lo[0]; i < box.hi[0]; ++i) {
          double sum = 0.0;
          std::uint64_t count = 0;
          const std::uint32_t c[3] = {i, j, k};
          std::uint64_t lo[3], hi[3];
          for (int a = 0; a < 3; ++a) {
            lo[a] = std::uint64_t{c[a]} << lod;
            hi[a] = std::min<std::uint64_t>((std::uint64_t{c[a]} + 1) << lod, v.dims[a]);
          }
          for (std::uint64_t z = lo[2]; z < hi[2]; ++z)
            for (std::uint64_t y = lo[1]; y < hi[1]; ++y)
              for (std::uint64_t x = lo[0]; x < hi[0]; ++x) {
                sum = sum + decode_value(v.encoding,
                                         fine[((z - full.lo[2]) * fy + (y - full.lo[1])) * fx + (x - full.lo[0])]);
                ++count;
              }
          bits[n++] = encode_value(v.encoding, sum / static_cast<double>(count));
        }
    return bits;
  }
  const std::uint64_t nx = box.hi[0] - box.lo[0], ny = box.hi[1] - box.lo[1];
  const std::uint64_t x_lo = std::uint64_t{box.lo[0]} << lod;
  const auto x_hi = static_cast<std::uint32_t>(std::min<std::uint64_t>(std::uint64_t{box.hi[0]} << lod, v.dims[0]));
  std::vector<std::uint32_t> bits = output_for<std::uint32_t>(box);
  std::vector<double> sums(nx * ny);
  std::size_t n = 0;
  for (std::uint32_t k = box.lo[2]; k < box.hi[2]; ++k) {
    // The blocks under one output layer at a time: a level of detail of a
    // large grid reads every block once, never more than the cache holds.
    impl.plan_box(Box{{box.lo[0], box.lo[1], k}, {box.hi[0], box.hi[1], k + 1}}, lod);
    std::fill(sums.begin(), sums.end(), 0.0);
    const std::uint64_t z_lo = std::uint64_t{k} << lod;
    const std::uint64_t z_hi = std::min<std::uint64_t>((std::uint64_t{k} + 1) << lod, v.dims[2]);
    const std::uint64_t y_lo = std::uint64_t{box.lo[1]} << lod;
    const std::uint64_t y_hi = std::min<std::uint64_t>(std::uint64_t{box.hi[1]} << lod, v.dims[1]);
    for (std::uint64_t z = z_lo; z < z_hi; ++z)
      for (std::uint64_t y = y_lo; y < y_hi; ++y) {
        const Box row{{static_cast<std::uint32_t>(x_lo), static_cast<std::uint32_t>(y), static_cast<std::uint32_t>(z)},
                      {x_hi, static_cast<std::uint32_t>(y + 1), static_cast<std::uint32_t>(z + 1)}};
        double* cells = sums.data() + ((y >> lod) - box.lo[1]) * nx;
        if (v.kind == StructureKind::Regular) {
          // A row of a regular grid is a run of consecutive values: take them
          // a block at a time rather than a cell at a time.
          const std::size_t width = encoding_width(v.encoding);
          std::uint64_t index = (z * v.dims[1] + y) * v.dims[0] + x_lo;
          for (std::uint64_t x = x_lo; x < x_hi;) {
            std::uint64_t run = 0;
            const std::uint8_t* p = impl.elements(3, index, &run);
            run = std::min<std::uint64_t>(run, x_hi - x);
            for (std::uint64_t i = 0; i < run; ++i, p += width) {
              const std::uint32_t bits =
                  width == 4 ? layout::load<std::uint32_t>(p) : std::uint32_t{layout::load<std::uint16_t>(p)};
              double& sum = cells[((x + i) >> lod) - box.lo[0]];
              sum = sum + decode_value(v.encoding, bits);
            }
            x += run;
            index += run;
          }
          continue;
        }
        // for_each_cell visits a row's cells in increasing x.
        grid.for_each_cell(row, [&](const Box& region, std::uint64_t index) {
          const double value = decode_value(v.encoding, impl.value_bits(index));
          for (std::uint64_t x = region.lo[0]; x < region.hi[0]; ++x) {
            double& sum = cells[(x >> lod) - box.lo[0]];
            sum = sum + value;
          }
        });
      }
    const std::uint64_t count_z = z_hi - z_lo;
    for (std::uint32_t j = box.lo[1]; j < box.hi[1]; ++j) {
      const std::uint64_t count_y =
          std::min<std::uint64_t>((std::uint64_t{j} + 1) << lod, v.dims[1]) - (std::uint64_t{j} << lod);
      for (std::uint32_t i = box.lo[0]; i < box.hi[0]; ++i) {
        const std::uint64_t count_x =
            std::min<std::uint64_t>((std::uint64_t{i} + 1) << lod, v.dims[0]) - (std::uint64_t{i} << lod);
        // The exact number of voxels, rounded once.
        const auto count = static_cast<double>(static_cast<u128>(count_z) * count_y * count_x);
        bits[n++] = encode_value(v.encoding, sums[(j - box.lo[1]) * nx + (i - box.lo[0])] / count);
      }
    }
  }
  return bits;
}

}  // namespace

Reader::Reader(const std::string& path, const ReaderOptions& options) : impl_(std::make_unique<Impl>(path, options)) {}
Reader::~Reader() = default;
Reader::Reader(Reader&&) noexcept = default;
Reader& Reader::operator=(Reader&&) noexcept = default;

const std::string& Reader::path() const { return impl_->file.path(); }
const FileInfo& Reader::info() const { return impl_->info; }
const VolumeLayout& Reader::layout() const { return impl_->info.layout; }
const Metadata& Reader::metadata() const { return impl_->metadata; }
const std::string& Reader::metadata_problem() const { return impl_->metadata_problem; }

bool is_remote_path(const std::string& path) { return detail::is_remote(path); }
const IoStats& Reader::io_stats() const {
  impl_->stats.bytes_read = impl_->file.bytes_read - impl_->bytes_baseline;
  impl_->stats.requests = impl_->file.requests() - impl_->requests_baseline;
  impl_->stats.bytes_fetched = impl_->file.bytes_fetched() - impl_->fetched_baseline;
  impl_->stats.fetched_whole = impl_->file.fetched_whole();
  return impl_->stats;
}

void Reader::reset_io_stats() {
  impl_->stats = IoStats{};
  impl_->bytes_baseline = impl_->file.bytes_read;
  impl_->requests_baseline = impl_->file.requests();
  impl_->fetched_baseline = impl_->file.bytes_fetched();
}

std::uint32_t Reader::voxel_bits(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod) {
  impl_->check_box(Box{{x, y, z}, {x + 1, y + 1, z + 1}}, lod);
  if (impl_->grid) return grid_bits(*impl_, Box{{x, y, z}, {x + 1, y + 1, z + 1}}, lod)[0];
  detail::ImplAccess access{impl_.get()};
  return detail::lookup_bits(access, impl_->info.layout, impl_->ranges, x, y, z, lod);
}

double Reader::voxel_value(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned lod) {
  const VolumeLayout& v = impl_->info.layout;
  return v.physical(decode_value(v.encoding, voxel_bits(x, y, z, lod)));
}

std::vector<float> Reader::read_box(const Box& box, unsigned lod, std::vector<DamagedRegion>* damaged) {
  impl_->check_box(box, lod);
  std::vector<float> out = output_for<float>(box);
  read_box_into(box, out.data(), lod, damaged);
  return out;
}

void Reader::read_box_into(const Box& box, float* out, unsigned lod, std::vector<DamagedRegion>* damaged) {
  impl_->check_box(box, lod);
  const VolumeLayout& v = impl_->info.layout;
  if (detail::grid_copies(*impl_, lod) && !damaged) {
    if (encoding_width(v.encoding) == 2) {
      const std::vector<float> table = physical_table(v);
      detail::copy_grid(*impl_, box, out, [&](std::uint32_t bits) { return table[bits]; });
    } else {
      detail::copy_grid(*impl_, box, out, [&](std::uint32_t bits) {
        return static_cast<float>(v.physical(decode_value(v.encoding, bits)));
      });
    }
    return;
  }
  const unsigned whole_level = damaged ? 0 : detail::whole_level_threads(*impl_, box, lod);
  if (!impl_->grid && !whole_level) impl_->plan_box(box, lod);
  if (impl_->grid && lod == 0) impl_->plan_box(box, lod);
  std::optional<detail::SalvageLog> log;
  if (damaged) log.emplace(detail::SalvageLog{*damaged});
  if (impl_->grid) {
    const std::vector<std::uint32_t> bits = grid_bits(*impl_, box, lod, log ? &*log : nullptr);
    for (std::size_t i = 0; i < bits.size(); ++i)
      out[i] = static_cast<float>(v.physical(decode_value(v.encoding, bits[i])));
    return;
  }
  // The octree: a whole level on several threads, else the one-thread walk.
  auto walk = [&](auto convert, detail::CubeWriter cube = nullptr) {
    auto sink = detail::box_output(out, box, convert, cube);
    if (whole_level) {
      detail::read_whole_level(*impl_, lod, sink, whole_level);
      return;
    }
    detail::ImplAccess access{impl_.get()};
    detail::walk_box(access, v, impl_->ranges, box, lod, sink, log ? &*log : nullptr);
  };
  if (v.encoding == ValueEncoding::UInt16) {
    // decode_value of a uint16 code is the code: converted inline, cheaper
    // than a lookup in a 256 KiB table at every voxel.
    // The scale and offset copied: read through `v` they are reloaded after
    // every store to the output, which might alias them.
    const double scale = v.value_scale, offset = v.value_offset;
    const bool identity = scale == 1.0 && offset == 0.0;  // VolumeLayout::physical's rule
    walk(
        [scale, offset, identity](std::uint32_t bits) {
          const auto code = static_cast<double>(bits & 0xFFFFu);
          return static_cast<float>(identity ? code : offset + scale * code);
        },
        identity ? detail::uint16_cube_writer() : nullptr);
    return;
  }
  if (v.encoding == ValueEncoding::Binary16 && box.voxel_count() >= 65536) {
    // Physical values of all 65536 codes, once per call: cheaper than
    // decoding each voxel when the box is large.
    const std::vector<float> table = physical_table(v);
    const float* physical = table.data();
    const bool identity = v.value_scale == 1.0 && v.value_offset == 0.0;  // VolumeLayout::physical's rule
    walk([physical](std::uint32_t bits) { return physical[bits & 0xFFFFu]; },
         identity ? detail::binary16_cube_writer() : nullptr);
    return;
  }
  walk([&v](std::uint32_t bits) { return static_cast<float>(v.physical(decode_value(v.encoding, bits))); });
}

std::vector<std::uint8_t> Reader::read_box_bits(const Box& box, unsigned lod, std::vector<DamagedRegion>* damaged) {
  impl_->check_box(box, lod);
  std::vector<std::uint8_t> out = output_for<std::uint8_t>(box, encoding_width(impl_->info.layout.encoding));
  read_box_bits_into(box, out.data(), lod, damaged);
  return out;
}

void Reader::read_box_bits_into(const Box& box, void* out_bytes, unsigned lod, std::vector<DamagedRegion>* damaged) {
  impl_->check_box(box, lod);
  const VolumeLayout& v = impl_->info.layout;
  const std::size_t width = encoding_width(v.encoding);
  auto* out = static_cast<std::uint8_t*>(out_bytes);
  if (detail::grid_copies(*impl_, lod) && !damaged) {
    if (width == 2)
      detail::copy_grid(*impl_, box, reinterpret_cast<std::uint16_t*>(out),
                        [](std::uint32_t bits) { return static_cast<std::uint16_t>(bits); });
    else
      detail::copy_grid(*impl_, box, reinterpret_cast<std::uint32_t*>(out), [](std::uint32_t bits) { return bits; });
    return;
  }
  const unsigned whole_level = damaged ? 0 : detail::whole_level_threads(*impl_, box, lod);
  if (!impl_->grid && !whole_level) impl_->plan_box(box, lod);
  if (impl_->grid && lod == 0) impl_->plan_box(box, lod);
  std::optional<detail::SalvageLog> log;
  if (damaged) log.emplace(detail::SalvageLog{*damaged});
  if (impl_->grid) {
    const std::vector<std::uint32_t> bits = grid_bits(*impl_, box, lod, log ? &*log : nullptr);
    for (std::size_t i = 0; i < bits.size(); ++i) std::memcpy(out + i * width, &bits[i], width);
    return;
  }
  auto walk = [&](auto* typed) {
    using T = std::remove_pointer_t<decltype(typed)>;
    auto sink = detail::box_output(typed, box, [](std::uint32_t bits) { return static_cast<T>(bits); });
    if (whole_level) {
      detail::read_whole_level(*impl_, lod, sink, whole_level);
      return;
    }
    detail::ImplAccess access{impl_.get()};
    detail::walk_box(access, v, impl_->ranges, box, lod, sink, log ? &*log : nullptr);
  };
  if (width == 2)
    walk(reinterpret_cast<std::uint16_t*>(out));
  else
    walk(reinterpret_cast<std::uint32_t*>(out));
}

void Reader::visit_leaves(const Box& box, unsigned lod, const std::function<void(const Box&, double)>& visit) {
  impl_->check_box(box, lod);
  const VolumeLayout& v = impl_->info.layout;
  if (impl_->grid && lod == 0) {
    impl_->grid->for_each_cell(box, [&](const Box& region, std::uint64_t index) {
      visit(region, v.physical(decode_value(v.encoding, impl_->value_bits(index))));
    });
    return;
  }
  if (impl_->grid) {  // a level of detail of a grid: each element on its own
    const std::vector<std::uint32_t> bits = grid_bits(*impl_, box, lod);
    std::size_t n = 0;
    for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
      for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
        for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x)
          visit(Box{{x, y, z}, {x + 1, y + 1, z + 1}}, v.physical(decode_value(v.encoding, bits[n++])));
    return;
  }
  detail::ImplAccess access{impl_.get()};
  detail::walk_box(access, v, impl_->ranges, box, lod, [&](const Box& region, std::uint32_t bits) {
    visit(region, v.physical(decode_value(v.encoding, bits)));
  });
}

std::vector<float> Reader::read_slice(Axis axis, std::uint32_t index) {
  return read_box(slice_box(impl_->info.layout.dims, axis, index));
}

std::vector<float> Reader::read_lod(unsigned lod) {
  if (lod > impl_->info.layout.depth) impl_->check_box(Box{}, lod);
  return read_box(full_box(impl_->info.layout.dims, lod), lod);
}

double Reader::sample(double wx, double wy, double wz) {
  const VolumeLayout& v = impl_->info.layout;
  const Metadata& m = impl_->metadata;
  const double world[3] = {wx, wy, wz};
  std::uint32_t lo[3];
  std::uint32_t hi[3];
  double frac[3];
  for (int a = 0; a < 3; ++a) {
    const double p = (world[a] - m.origin[a]) / m.voxel_size[a];
    const double limit = static_cast<double>(v.dims[a] - 1);
    const double clamped = std::isnan(p) ? 0.0 : std::min(std::max(p, 0.0), limit);
    lo[a] = static_cast<std::uint32_t>(std::floor(clamped));
    hi[a] = std::min(lo[a] + 1, v.dims[a] - 1);
    frac[a] = clamped - lo[a];
  }
  double result = 0.0;
  for (unsigned c = 0; c < 8; ++c) {
    double weight = 1.0;
    std::uint32_t at[3];
    for (int a = 0; a < 3; ++a) {
      const bool upper = (c >> a) & 1u;
      at[a] = upper ? hi[a] : lo[a];
      weight *= upper ? frac[a] : 1.0 - frac[a];
    }
    if (weight != 0.0) result += weight * voxel_value(at[0], at[1], at[2]);
  }
  return result;
}

std::vector<std::uint8_t> Reader::read_block(std::size_t block_index) {
  if (block_index >= impl_->info.blocks.size())
    throw Error(ErrorClass::InvalidArgument, path() + ": no block " + std::to_string(block_index));
  const BlockInfo& b = impl_->info.blocks[block_index];
  return detail::read_and_decode_block(impl_->file, b, block_index,
                                       detail::stream_width(b.stream, impl_->info.layout.encoding),
                                       detail::is_known_stream(b.stream, impl_->info.layout.kind), impl_->info.framed(),
                                       detail::brick_of_block(impl_->info.layout, b.stream, b.level, b.first_element));
}

}  // namespace ivol
