// The samples of a MetaImage or NRRD file (itk_image_header.hpp), read by
// range: raw data by pread, compressed data (zlib or gzip) by inflating
// forward from the start of the stream, so that reading a file in order
// costs one pass and memory of one request. A request before the position
// reached starts the stream again (for random access to compressed data,
// inflate_to_file() gives an uncompressed copy once).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <zlib.h>

#include "itk_image_header.hpp"

namespace ivol::convert {

class ImageSamples {
 public:
  // Checks that the data file holds what the header says (raw: exactly the
  // samples' bytes after the offset).
  explicit ImageSamples(const ImageHeader& header);
  ~ImageSamples();
  ImageSamples(const ImageSamples&) = delete;
  ImageSamples& operator=(const ImageSamples&) = delete;

  const ImageHeader& header() const { return header_; }
  // Samples [first, first + count) in native byte order, as stored (no
  // conversion of type). A compressed stream that ends early, holds more
  // than the samples, or is damaged is an error naming the file and where.
  void read(std::uint64_t first, std::uint64_t count, void* out);

  // A compressed file: inflates it whole into an unlinked temporary file
  // (in TMPDIR) and reads from there from now on. Checks the stream's end.
  void inflate_to_file();

 private:
  void read_raw(std::uint64_t at, std::uint64_t size, std::uint8_t* out);
  void inflate(std::uint64_t at, std::uint64_t size, std::uint8_t* out);
  void restart();
  std::uint64_t produce(std::uint8_t* out, std::uint64_t size);  // the next `size` bytes of the stream
  std::string where(std::uint64_t at) const;

  ImageHeader header_;
  int fd_ = -1;
  std::uint64_t data_end_ = 0;  // end of the (compressed) data in the file
  // Compressed reading.
  z_stream stream_{};
  bool stream_open_ = false;
  bool stream_ended_ = false;
  std::uint64_t file_at_ = 0;   // next compressed byte to feed
  std::uint64_t produced_ = 0;  // bytes of samples inflated so far
  std::vector<std::uint8_t> input_;
  std::vector<std::uint8_t> skip_;
  bool inflated_to_file_ = false;
};

}  // namespace ivol::convert
