#include "output_rules.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "ivol/error.hpp"
#include "ivol/temporary_file.hpp"
#include "option_parsing.hpp"

namespace ivol::cli {
namespace {

namespace fs = std::filesystem;

const char* kind_of(mode_t mode) {
  if (S_ISLNK(mode)) return "a symbolic link";
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode) || S_ISBLK(mode)) return "a device";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

// Where a path leads, for comparing names that need not exist yet.
fs::path resolved(const std::string& path) {
  std::error_code ec;
  const fs::path absolute = fs::absolute(path).lexically_normal();
  fs::path p = fs::weakly_canonical(absolute, ec);
  return ec ? absolute : p;
}

bool same_file(const struct stat& a, const struct stat& b) { return a.st_dev == b.st_dev && a.st_ino == b.st_ino; }

void check_one(const OutputFile& out, const std::vector<std::string>& inputs, bool force) {
  const std::string& path = out.path;
  if (path.empty()) throw UsageError(out.option, "the output's name is empty");
  if (is_stdio(path)) {
    if (!out.stdout_allowed) throw UsageError(out.option, "'-' (standard output) takes raw output only; name a file");
    if (::isatty(STDOUT_FILENO))
      throw UsageError(out.option, "standard output is a terminal; not writing binary to it");
    return;
  }
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISREG(st.st_mode))
      throw UsageError(out.option,
                       path + ": is " + kind_of(st.st_mode) + "; only a regular file is ever replaced" +
                           (S_ISLNK(st.st_mode) ? " (name the file it points to, or remove the link)" : ""));
    for (const std::string& input : inputs) {
      struct stat in {};
      if (!is_stdio(input) && ::stat(input.c_str(), &in) == 0 && same_file(st, in))
        throw UsageError(out.option, path + ": is the input " + input + " (the same file); write somewhere else");
    }
    if (!force) throw UsageError(out.option, path + ": exists (use --force to replace it)");
  } else if (errno != ENOENT) {
    throw Error(ErrorClass::Io, path + ": cannot inspect the output: " + std::strerror(errno));
  }
  // The folder it goes into: an input folder (a TIFF stack would take it as a
  // slice), or none at all, is refused before the work rather than after.
  const fs::path folder = resolved(path).parent_path();
  for (const std::string& input : inputs) {
    std::error_code ec;
    if (!is_stdio(input) && fs::is_directory(input, ec) && resolved(input) == folder)
      throw UsageError(out.option, path + ": is inside the input folder " + input + "; write somewhere else");
  }
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw Error(ErrorClass::Io, path + ": the folder " + folder.string() + " does not exist");
  if (!force) ivol::refuse_to_replace(path);
}

}  // namespace

void check_outputs(const std::vector<OutputFile>& outputs, const std::vector<std::string>& inputs, bool force) {
  for (const OutputFile& out : outputs) check_one(out, inputs, force);
  for (std::size_t a = 0; a < outputs.size(); ++a)
    for (std::size_t b = a + 1; b < outputs.size(); ++b)
      if (!is_stdio(outputs[a].path) && resolved(outputs[a].path) == resolved(outputs[b].path))
        throw UsageError(outputs[b].option, outputs[b].path + ": is also " + outputs[a].option + "; name two files");
}

std::string lower_extension(const std::string& path) {
  std::string e = fs::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace ivol::cli
