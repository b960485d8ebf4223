// The rules every file the command line writes follows, checked before any
// work so that a refused output costs nothing:
// - only a regular file is ever replaced: a symbolic link (dangling or not),
//   a directory, a device, a FIFO or a socket at the output's name is
//   refused, even with -f;
// - an existing file is replaced only with -f, and without -f the final
//   rename cannot replace a file that appeared meanwhile
//   (ivol::refuse_to_replace);
// - an output is never one of the inputs (same device and inode, hard links
//   included), nor inside an input folder, nor named twice, even with -f;
// - "-" is standard output where a command allows it, and never a terminal.
// A refusal is a bad command line (UsageError, exit 1).
#pragma once

#include <string>
#include <vector>

namespace ivol::cli {

struct OutputFile {
  std::string path;
  const char* option;   // how the command line names it, for messages
  bool stdout_allowed;  // "-" means standard output
};

void check_outputs(const std::vector<OutputFile>& outputs, const std::vector<std::string>& inputs, bool force);
inline void check_output(const std::string& path, const char* option, const std::vector<std::string>& inputs,
                         bool force, bool stdout_allowed = false) {
  check_outputs({{path, option, stdout_allowed}}, inputs, force);
}

inline bool is_stdio(const std::string& path) { return path == "-"; }

// "ext" of a path, lower case, with its dot (".tif"); empty when none.
std::string lower_extension(const std::string& path);

}  // namespace ivol::cli
