// The ivol subcommands. Each registers itself on the application and returns
// the function that runs it; the functions return the process exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <string>

namespace ivol::cli {

// Exit codes of every subcommand.
constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;     // bad command line
constexpr int kExitFailure = 2;   // bad input file, damaged file, I/O error
constexpr int kExitSalvaged = 3;  // output written, but parts of it came from coarser levels (--salvage)

struct GlobalOptions {
  bool quiet = false;
  bool verbose = false;
  std::string command_line;  // argv, shell-quoted: provenance.command
};

using Runner = std::function<int()>;

Runner add_demo_command(CLI::App& app, const GlobalOptions& global);
Runner add_info_command(CLI::App& app, const GlobalOptions& global);
Runner add_verify_command(CLI::App& app, const GlobalOptions& global);
Runner add_convert_command(CLI::App& app, const GlobalOptions& global);
Runner add_extract_command(CLI::App& app, const GlobalOptions& global);
Runner add_slice_command(CLI::App& app, const GlobalOptions& global);
Runner add_phantom_command(CLI::App& app, const GlobalOptions& global);
Runner add_devices_command(CLI::App& app, const GlobalOptions& global);
Runner add_recon_command(CLI::App& app, const GlobalOptions& global);

}  // namespace ivol::cli
