// Where the reconstruction gets its projections from: line integrals
// (−log of transmitted over incident intensity), read a band of detector rows
// at a time so that a slab of the volume reads only the rows it needs and a
// scan larger than memory is never held whole.
#pragma once

#include <cstddef>
#include <vector>

namespace ivol::recon {

class ProjectionSource {
 public:
  virtual ~ProjectionSource() = default;
  virtual int columns() const = 0;
  virtual int rows() const = 0;
  virtual std::size_t view_count() const = 0;
  // Writes rows [row_begin, row_end) of view `view` as line integrals,
  // row-major with columns fastest, into `out` (columns · (row_end −
  // row_begin) floats). Called from one thread at a time; throws
  // std::runtime_error naming the file and view on failure.
  virtual void read_rows(std::size_t view, int row_begin, int row_end, float* out) = 0;
};

// Projections already in memory (phantoms, tests): view-major, then rows,
// then columns.
class InMemoryProjections : public ProjectionSource {
 public:
  InMemoryProjections(int columns, int rows, std::size_t view_count);
  InMemoryProjections(int columns, int rows, std::size_t view_count, std::vector<float> data);
  int columns() const override { return columns_; }
  int rows() const override { return rows_; }
  std::size_t view_count() const override { return views_; }
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override;

  float* view_data(std::size_t view) { return data_.data() + view * image_size(); }
  const float* view_data(std::size_t view) const { return data_.data() + view * image_size(); }
  std::vector<float>& data() { return data_; }
  std::size_t image_size() const { return static_cast<std::size_t>(columns_) * static_cast<std::size_t>(rows_); }

 private:
  int columns_;
  int rows_;
  std::size_t views_;
  std::vector<float> data_;
};

}  // namespace ivol::recon

namespace ivol::recon {

// A coarser view of a scan, for quick low-resolution reconstructions (the
// paper's preview): every `view_step`-th view, detector pixels averaged in
// `bin` × `bin` blocks (a last partial block is dropped). Reads through the
// source, a band of rows at a time.
class ReducedProjections : public ProjectionSource {
 public:
  ReducedProjections(ProjectionSource& source, unsigned view_step, unsigned bin);
  int columns() const override { return source_.columns() / static_cast<int>(bin_); }
  int rows() const override { return source_.rows() / static_cast<int>(bin_); }
  std::size_t view_count() const override { return (source_.view_count() + view_step_ - 1) / view_step_; }
  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override;

 private:
  ProjectionSource& source_;
  unsigned view_step_;
  unsigned bin_;
  std::vector<float> scratch_;
};

}  // namespace ivol::recon
