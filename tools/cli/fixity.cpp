#include "fixity.hpp"

#include <glob.h>

#include <filesystem>
#include <system_error>

#include "ivol/error.hpp"
#include "stdio_volume.hpp"
#include "tiff_io.hpp"

namespace ivol::cli {

std::vector<std::string> input_files(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    std::vector<std::string> files;
    for (const std::string& name : convert::natural_sorted_files(path)) files.push_back(path + "/" + name);
    return files;
  }
  if (std::filesystem::exists(path, ec) || path.find_first_of("*?[") == std::string::npos) return {path};
  glob_t matches{};
  std::vector<std::string> files;
  if (::glob(path.c_str(), 0, nullptr, &matches) == 0)
    for (std::size_t i = 0; i < matches.gl_pathc; ++i) files.emplace_back(matches.gl_pathv[i]);
  ::globfree(&matches);
  return files.empty() ? std::vector<std::string>{path} : files;
}

std::string manifest_digest(const std::vector<FileDigest>& files, const std::string& folder) {
  Sha256 sha;
  for (const FileDigest& f : files) {
    const std::string name = std::filesystem::path(f.path).lexically_relative(folder).string();
    const std::string line = f.sha256 + "  " + name + "\n";
    sha.update(line.data(), line.size());
  }
  return sha.hex();
}

SourceDigests::SourceDigests(const std::vector<std::string>& inputs, const std::vector<nlohmann::json>& fields)
    : inputs_(inputs), fields_(fields), digests_(inputs.size()) {
  try {
    thread_ = std::thread([this] { hash_inputs(); });
  } catch (const std::system_error&) {
    // No thread to be had (a process or address-space limit): sources()
    // hashes them itself, after the conversion.
  }
}

void SourceDigests::hash_inputs() {
  hashed_ = true;
  try {
    for (std::size_t i = 0; i < inputs_.size(); ++i)
      if (inputs_[i] != "-")  // standard input is read once, by the conversion
        for (const std::string& file : input_files(inputs_[i])) {
          if (cancel_) return;
          digests_[i].push_back(digest_file(file, &cancel_));
        }
  } catch (...) {
    failure_ = std::current_exception();
  }
}

SourceDigests::~SourceDigests() {
  cancel_ = true;
  if (thread_.joinable()) thread_.join();
}

nlohmann::json SourceDigests::sources() {
  if (thread_.joinable()) thread_.join();
  if (!hashed_) hash_inputs();
  if (failure_) std::rethrow_exception(failure_);
  nlohmann::json list = nlohmann::json::array();
  for (std::size_t i = 0; i < inputs_.size(); ++i) {
    const nlohmann::json& extra = i < fields_.size() ? fields_[i] : nlohmann::json::object();
    if (inputs_[i] == "-") {
      // Hashed by the reader as it read (no second pass over a stream).
      const StdinDigest d = stdin_digest();
      nlohmann::json entry = {{"path", "-"}};
      if (!d.sha256.empty()) entry.update({{"bytes", d.bytes}, {"sha256", d.sha256}});
      entry.update(extra);
      list.push_back(entry);
      continue;
    }
    if (digests_[i].size() > kMaxListedFiles) {
      std::uint64_t bytes = 0;
      for (const FileDigest& f : digests_[i]) bytes += f.bytes;
      nlohmann::json entry = {{"path", inputs_[i]},
                              {"files", digests_[i].size()},
                              {"bytes", bytes},
                              {"manifest_sha256", manifest_digest(digests_[i], inputs_[i])}};
      entry.update(extra);
      list.push_back(entry);
      continue;
    }
    for (const FileDigest& f : digests_[i]) {
      nlohmann::json entry = {{"path", f.path}, {"bytes", f.bytes}, {"sha256", f.sha256}};
      entry.update(extra);
      list.push_back(entry);
    }
  }
  return list;
}

std::function<void(Metadata&)> SourceDigests::filler(std::shared_ptr<SourceDigests> digests) {
  return [digests](Metadata& m) { m.provenance["sources"] = digests->sources(); };
}

std::string shell_quote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=./,:@%") ==
                        std::string::npos)
    return s;
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string quoted_command_line(int argc, char** argv) {
  std::string line;
  for (int i = 0; i < argc; ++i) {
    // The program as people call it, not the build tree's path to it.
    const std::string word = i == 0 ? std::filesystem::path(argv[0]).filename().string() : argv[i];
    line += (i ? " " : "") + shell_quote(word);
  }
  return line;
}

}  // namespace ivol::cli
