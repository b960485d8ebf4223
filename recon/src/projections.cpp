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
