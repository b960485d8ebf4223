#include "formats.hpp"

#include <filesystem>

#include "ivol/error.hpp"
#include "tiff_io.hpp"

namespace ivol::cli {

const char* format_name(Format format) {
  switch (format) {
    case Format::Ivol:
      return "ivol";
    case Format::Raw:
      return "raw";
    case Format::Tiff:
      return "tiff";
    case Format::Hdf5:
      return "hdf5";
    case Format::Vdb:
      return "vdb";
  }
  return "?";
}

Format detect_format(const std::string& path, const std::string& name, const char* option) {
  const std::string key = !name.empty() ? name : std::filesystem::path(path).extension().string();
  if (key == "ivol" || key == ".ivol") return Format::Ivol;
  if (key == "raw" || key == ".raw" || key == ".bin" || key == ".vol") return Format::Raw;
  if (key == "tiff" || key == "tif" || key == ".tif" || key == ".tiff") return Format::Tiff;
  if (key == "hdf5" || key == ".h5" || key == ".hdf5" || key == ".hdf") return Format::Hdf5;
  if (key == "vdb" || key == ".vdb") return Format::Vdb;
  if (name.empty() && std::filesystem::is_directory(path)) return Format::Tiff;
  throw Error(
      ErrorClass::InvalidArgument,
      std::string(option) + ": cannot tell the format of '" + path +
          "' (extensions .ivol .raw .bin .vol .tif .tiff .h5 .hdf5 .vdb, or a folder of TIFF files; or name it)");
}

convert::DenseVolume read_dense(const std::string& path, Format format, const ForeignOptions& options) {
  switch (format) {
    case Format::Raw:
      if (!options.raw_dims_given)
        throw Error(ErrorClass::InvalidArgument, "--dims: a raw input needs its dimensions (--dims X,Y,Z --type T)");
      return convert::read_raw(path, options.raw);
    case Format::Tiff:
      return convert::read_tiff(path);
    case Format::Hdf5:
    case Format::Vdb:
      throw Error(ErrorClass::InvalidArgument,
                  std::string(format_name(format)) + " is not supported by this build of ivol yet");
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

void write_dense(const convert::DenseVolume& volume, const std::string& path, Format format,
                 const ForeignOptions& options) {
  switch (format) {
    case Format::Raw:
      return convert::write_raw(volume, path, options.big_endian);
    case Format::Tiff:
      return convert::write_tiff(volume, path);
    case Format::Hdf5:
    case Format::Vdb:
      throw Error(ErrorClass::InvalidArgument,
                  std::string(format_name(format)) + " is not supported by this build of ivol yet");
    case Format::Ivol:
      break;
  }
  throw Error(ErrorClass::InvalidArgument, path + ": .ivol is not a dense format");
}

}  // namespace ivol::cli
