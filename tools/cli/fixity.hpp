// Fixity of conversions: the digests of the files a conversion read, for
// provenance.sources (spec §11), and the command line that ran it.
#pragma once

#include <exception>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "ivol/metadata.hpp"
#include "sha256.hpp"

namespace ivol::cli {

// The files an input path stands for: the file itself, every regular file of
// a folder (in the natural order the TIFF reader uses), or a glob's matches.
std::vector<std::string> input_files(const std::string& path);

// A folder of more files than this is recorded as one entry (its file count,
// total bytes and the SHA-256 of its manifest lines) rather than one entry per
// file, to keep the metadata small (10 000 entries are about 1.5 MB of JSON).
constexpr std::size_t kMaxListedFiles = 10000;

// The SHA-256 of manifest lines "<sha256>  <name>\n" for `files` in order,
// with names relative to `folder`: a folder's digest.
std::string manifest_digest(const std::vector<FileDigest>& files, const std::string& folder);

// Hashes input files on a thread of its own while the conversion reads them:
// both read the same pages, so the second read comes from the page cache and
// the hashing (1.3 GB/s per core with SHA-NI on the development machine)
// overlaps the conversion where a core is free (README: its cost).
class SourceDigests {
 public:
  // inputs: the paths given on the command line (files, folders, globs);
  // `fields`: added to each input's entries (format, sample type...).
  SourceDigests(const std::vector<std::string>& inputs, const std::vector<nlohmann::json>& fields);
  ~SourceDigests();  // stops hashing that sources() did not wait for
  SourceDigests(const SourceDigests&) = delete;
  SourceDigests& operator=(const SourceDigests&) = delete;
  // Waits for the digests; provenance.sources. Throws the hashing's error.
  nlohmann::json sources();
  // For ImportOptions::complete_metadata: sets provenance.sources.
  static std::function<void(Metadata&)> filler(std::shared_ptr<SourceDigests> digests);

 private:
  std::vector<std::string> inputs_;
  std::vector<nlohmann::json> fields_;
  std::vector<std::vector<FileDigest>> digests_;  // per input
  std::exception_ptr failure_;
  std::atomic<bool> cancel_{false};  // the conversion failed: stop hashing
  bool hashed_ = false;              // hash_inputs() ran (on thread_ or in sources())
  std::thread thread_;
  void hash_inputs();
};

// argv as one line a POSIX shell reads back as the same words.
std::string shell_quote(const std::string& word);
std::string quoted_command_line(int argc, char** argv);

}  // namespace ivol::cli
