// A TIFF stack for peers_bench, through libtiff: a folder of one file per
// z-slice, 16-bit IEEE floats (SampleFormat 3, 16 bits), deflate (zlib level
// 6, libtiff's default), strips of libtiff's default size (about 8 KiB), no
// predictor. With a keep mask, voxels outside it hold the background value.
//
// A box reads the files of its slices and, in each, only the strips holding
// its rows. Files are opened with memory mapping off ("rm"), so that what
// libtiff reads goes through read() and /proc/self/io counts it.
#include <tiffio.h>

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "ivol/binary16.hpp"
#include "peer_format.hpp"

namespace peers {

std::string tiff_version() {
  const std::string text = TIFFGetVersion();
  const auto newline = text.find('\n');
  return newline == std::string::npos ? text : text.substr(0, newline);
}

namespace {

std::string slice_path(const std::string& folder, std::uint32_t z) {
  char name[32];
  std::snprintf(name, sizeof name, "/slice_%05u.tif", z);
  return folder + name;
}

class TiffStack : public PeerFormat {
 public:
  std::string name() const override { return "TIFF stack deflate"; }
  std::string details() const override {
    return "binary16 (SampleFormat IEEEFP, 16 bits), one file per slice, deflate";
  }

  void write(const VolumeCase& volume, const std::string& path) override {
    std::filesystem::create_directories(path);
    const std::uint32_t n = volume.n;
    const std::uint16_t background = ivol::float_to_binary16(volume.background);
    std::vector<std::uint16_t> row(n);
    for (std::uint32_t z = 0; z < n; ++z) {
      TIFF* tiff = TIFFOpen(slice_path(path, z).c_str(), "w");
      if (!tiff) throw std::runtime_error("cannot write " + slice_path(path, z));
      TIFFSetField(tiff, TIFFTAG_IMAGEWIDTH, n);
      TIFFSetField(tiff, TIFFTAG_IMAGELENGTH, n);
      TIFFSetField(tiff, TIFFTAG_BITSPERSAMPLE, 16);
      TIFFSetField(tiff, TIFFTAG_SAMPLEFORMAT, SAMPLEFORMAT_IEEEFP);
      TIFFSetField(tiff, TIFFTAG_SAMPLESPERPIXEL, 1);
      TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
      TIFFSetField(tiff, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
      TIFFSetField(tiff, TIFFTAG_COMPRESSION, COMPRESSION_ADOBE_DEFLATE);
      TIFFSetField(tiff, TIFFTAG_ROWSPERSTRIP, TIFFDefaultStripSize(tiff, 0));
      for (std::uint32_t y = 0; y < n; ++y) {
        const std::uint64_t first = (std::uint64_t{z} * n + y) * n;
        for (std::uint32_t x = 0; x < n; ++x) {
          const bool kept = !volume.keep || (*volume.keep)[first + x];
          row[x] = kept ? ivol::float_to_binary16((*volume.values)[first + x]) : background;
        }
        if (TIFFWriteScanline(tiff, row.data(), y, 0) < 0) {
          TIFFClose(tiff);
          throw std::runtime_error("cannot write " + slice_path(path, z));
        }
      }
      TIFFClose(tiff);
    }
  }

  std::vector<float> read_box(const std::string& path, std::uint32_t n, const ivol::Box& box) override {
    std::vector<float> out(box.voxel_count());
    float* next = out.data();
    for (std::uint32_t z = box.lo[2]; z < box.hi[2]; ++z) {
      TIFF* tiff = TIFFOpen(slice_path(path, z).c_str(), "rm");
      if (!tiff) throw std::runtime_error("cannot read " + slice_path(path, z));
      std::uint32_t rows_per_strip = 0;
      TIFFGetFieldDefaulted(tiff, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
      std::vector<std::uint16_t> strip(std::size_t{rows_per_strip} * n);
      std::uint32_t loaded = UINT32_MAX;
      for (std::uint32_t y = box.lo[1]; y < box.hi[1]; ++y) {
        const std::uint32_t wanted = y / rows_per_strip;
        if (wanted != loaded) {
          if (TIFFReadEncodedStrip(tiff, wanted, strip.data(), static_cast<tmsize_t>(strip.size() * 2)) < 0) {
            TIFFClose(tiff);
            throw std::runtime_error("cannot read " + slice_path(path, z));
          }
          loaded = wanted;
        }
        const std::uint16_t* row = strip.data() + std::size_t{y % rows_per_strip} * n;
        for (std::uint32_t x = box.lo[0]; x < box.hi[0]; ++x) *next++ = ivol::binary16_to_float(row[x]);
      }
      TIFFClose(tiff);
    }
    return out;
  }
};

}  // namespace

void write_uint16_tiff_stack(const std::vector<std::uint16_t>& volume, std::uint32_t n, const std::string& folder) {
  std::filesystem::create_directories(folder);
  for (std::uint32_t z = 0; z < n; ++z) {
    TIFF* tiff = TIFFOpen(slice_path(folder, z).c_str(), "w");
    if (!tiff) throw std::runtime_error("cannot write " + slice_path(folder, z));
    TIFFSetField(tiff, TIFFTAG_IMAGEWIDTH, n);
    TIFFSetField(tiff, TIFFTAG_IMAGELENGTH, n);
    TIFFSetField(tiff, TIFFTAG_BITSPERSAMPLE, 16);
    TIFFSetField(tiff, TIFFTAG_SAMPLEFORMAT, SAMPLEFORMAT_UINT);
    TIFFSetField(tiff, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    TIFFSetField(tiff, TIFFTAG_COMPRESSION, COMPRESSION_NONE);
    TIFFSetField(tiff, TIFFTAG_ROWSPERSTRIP, TIFFDefaultStripSize(tiff, 0));
    for (std::uint32_t y = 0; y < n; ++y) {
      auto* row = const_cast<std::uint16_t*>(volume.data() + (std::uint64_t{z} * n + y) * n);
      if (TIFFWriteScanline(tiff, row, y, 0) < 0) {
        TIFFClose(tiff);
        throw std::runtime_error("cannot write " + slice_path(folder, z));
      }
    }
    TIFFClose(tiff);
  }
}

std::vector<std::unique_ptr<PeerFormat>> tiff_formats() {
  std::vector<std::unique_ptr<PeerFormat>> formats;
  formats.push_back(std::make_unique<TiffStack>());
  return formats;
}

}  // namespace peers
