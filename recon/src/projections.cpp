#include "ivol/recon/projections.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace ivol::recon {

InMemoryProjections::InMemoryProjections(int columns, int rows, std::size_t view_count)
    : InMemoryProjections(columns, rows, view_count,
                          std::vector<float>(static_cast<std::size_t>(columns) * rows * view_count, 0.0F)) {}

InMemoryProjections::InMemoryProjections(int columns, int rows, std::size_t view_count, std::vector<float> data)
    : columns_(columns), rows_(rows), views_(view_count), data_(std::move(data)) {
  if (columns <= 0 || rows <= 0) throw std::invalid_argument("projections: detector size must be positive");
  if (data_.size() != image_size() * views_)
    throw std::invalid_argument("projections: " + std::to_string(data_.size()) + " values given for " +
                                std::to_string(views_) + " views of " + std::to_string(columns) + "x" +
                                std::to_string(rows));
}

void InMemoryProjections::read_rows(std::size_t view, int row_begin, int row_end, float* out) {
  if (view >= views_ || row_begin < 0 || row_end > rows_ || row_begin > row_end)
    throw std::out_of_range("projections: rows " + std::to_string(row_begin) + ".." + std::to_string(row_end) +
                            " of view " + std::to_string(view) + " are outside the scan");
  const float* first = view_data(view) + static_cast<std::size_t>(row_begin) * columns_;
  std::copy(first, first + static_cast<std::size_t>(row_end - row_begin) * columns_, out);
}

}  // namespace ivol::recon

namespace ivol::recon {

ReducedProjections::ReducedProjections(ProjectionSource& source, unsigned view_step, unsigned bin)
    : source_(source), view_step_(view_step), bin_(bin) {
  if (view_step == 0 || bin == 0) throw std::invalid_argument("reduced projections: steps must be positive");
  if (columns() == 0 || rows() == 0)
    throw std::invalid_argument("reduced projections: binning by " + std::to_string(bin) + " leaves no pixels");
}

void ReducedProjections::read_rows(std::size_t view, int row_begin, int row_end, float* out) {
  if (row_end <= row_begin) return;
  const int b = static_cast<int>(bin_);
  const int source_columns = source_.columns();
  const int columns_out = columns();
  // Source rows are asked for in runs of up to 4 MiB, not one binned row
  // (b rows) at a time: each request to an HDF5 source is a round trip to
  // its child process and a 1 MiB buffer libhdf5 zeroes, which made the
  // detection preview of a 256³ run cost more than the dense FDK.
  constexpr std::size_t kRunFloats = std::size_t{1} << 20;
  const int run = static_cast<int>(
      std::clamp<std::size_t>(kRunFloats / (static_cast<std::size_t>(source_columns) * b), 1, row_end - row_begin));
  scratch_.resize(static_cast<std::size_t>(source_columns) * b * run);
  const float scale = 1.0F / static_cast<float>(b * b);
  for (int first = row_begin; first < row_end; first += run) {
    const int last = std::min(row_end, first + run);
    source_.read_rows(view * view_step_, first * b, last * b, scratch_.data());
    for (int r = first; r < last; ++r) {
      const float* rows = scratch_.data() + static_cast<std::size_t>(r - first) * b * source_columns;
      float* target = out + static_cast<std::size_t>(r - row_begin) * columns_out;
      for (int c = 0; c < columns_out; ++c) {
        float sum = 0.0F;
        for (int y = 0; y < b; ++y)
          for (int x = 0; x < b; ++x) sum += rows[static_cast<std::size_t>(y) * source_columns + c * b + x];
        target[c] = sum * scale;
      }
    }
  }
}

}  // namespace ivol::recon
