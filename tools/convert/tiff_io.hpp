// TIFF stacks through libtiff: one multi-page file, or a folder with one file
// per slice (sorted naturally: slice2 before slice10).
#pragma once

#include <string>
#include <vector>

#include "dense_volume.hpp"
#include "tiff_folder.hpp"

namespace ivol::convert {

// 8- and 16-bit integers (unsigned or signed 16) and 32-bit float, one sample
// per pixel; any compression libtiff decodes; tiled or striped. Every page must
// have the same size and sample format (else Error(Malformed) naming the page's
// own file). A folder is checked as tiff_folder.hpp says; geometry and
// metadata are read as tiff_metadata.hpp says.
DenseVolume read_tiff(const std::string& path_or_folder, const TiffFolderOptions& options = {});

struct TiffWriteOptions {
  bool compress = true;  // deflate with a predictor; false: uncompressed
};

// One multi-page file, BigTIFF when the volume approaches 4 GiB; written to a
// temporary file and renamed when complete. Carries the geometry and metadata
// as tiff_metadata.hpp says (ImageJ description, resolution, tag 65369).
void write_tiff(const DenseVolume& volume, const std::string& path, const TiffWriteOptions& options = {});

// Names of the regular files in `folder`, in natural order (digit runs
// compared as numbers).
std::vector<std::string> natural_sorted_files(const std::string& folder);

}  // namespace ivol::convert
