// A folder of TIFF slices, checked before it is trusted as a volume: the
// files must be numbered one slice each, without gaps or repeats.
//
// The rules (README "TIFF folders"):
//   - hidden files (a name starting with '.': macOS's AppleDouble "._s1.tif",
//     ".DS_Store", other dotfiles) are skipped, and the skipped TIFF-named
//     ones are listed in a note;
//   - the slice number of a file is the run of digits in its name (before
//     the extension) that changes from file to file (the last such run when
//     several change; the last run when none does); every file must have
//     digits, and the text around them must be the same for all files
//     (scan2_z0001.tif ... scan2_z0100.tif), else the order of the slices
//     is a guess: refused, naming the file;
//   - two files with the same number (s1.tif and s01.tif, s1.tif and
//     s1.tiff) are refused, naming both;
//   - the step is the smallest difference between consecutive numbers
//     (1 usually; a folder of every other slice has 2); a larger difference
//     is a gap, refused naming the files either side and the missing name,
//     unless allow_gaps, which converts what is there and says so in a note.
// A folder holding a single TIFF file needs no number.
#pragma once

#include <string>
#include <vector>

#include "ivol/error.hpp"

namespace ivol::convert {

struct TiffFolderOptions {
  bool allow_gaps = false;
  // What the refusal of a gap suggests.
  std::string gap_hint = "use --allow-gaps to convert anyway";
};

struct TiffFolder {
  std::vector<std::string> files;  // paths (folder/name), in slice order
  std::vector<std::string> notes;  // for the conversion summary
};

// Throws ivol::Error(Malformed) naming the offending files; Io when the
// folder cannot be listed; InvalidArgument when it holds no TIFF file.
TiffFolder scan_tiff_folder(const std::string& folder, const TiffFolderOptions& options = {});

// The refusal of a file with a second page among several files (`unit`:
// "slice", "projection"): the numbering counts one per file, so its other
// pages would move every later one along z (or in angle) unnoticed.
Error several_pages_among_files(const std::string& file, const std::string& unit);

}  // namespace ivol::convert
