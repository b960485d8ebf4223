// ivol verify FILE: every checksum and every structural rule; exit 0 only
// for a sound file.
#include <iostream>

#include "commands.hpp"
#include "ivol/check.hpp"

namespace ivol::cli {

Runner add_verify_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("verify", "Check every checksum and structural rule of .ivol files");
  auto files = std::make_shared<std::vector<std::string>>();
  cmd->add_option("FILE", *files, "The .ivol files")->required();
  return [files, &global]() {
    int status = kExitOk;
    for (const std::string& file : *files) {
      const CheckReport report = check_file(file);
      if (report.ok()) {
        if (!global.quiet)
          std::cout << file << ": OK (" << report.blocks_checked << " blocks, structure and averages verified)\n";
        continue;
      }
      status = kExitFailure;
      std::cout << file << ": DAMAGED (" << report.problems.size() << " problem"
                << (report.problems.size() == 1 ? "" : "s");
      if (report.blocks_checked)
        std::cout << ", " << report.blocks_damaged << " of " << report.blocks_checked << " blocks damaged";
      std::cout << ")\n";
      for (const CheckProblem& p : report.problems)
        std::cout << "  " << error_class_name(p.error_class) << ": " << p.message << "\n";
    }
    return status;
  };
}

}  // namespace ivol::cli
