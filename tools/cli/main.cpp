// ivol: the command line of the ivol toolkit. Uses libformat's public API only.
#include <iostream>
#include <map>
#include <new>
#include <stdexcept>
#include <system_error>

#include "commands.hpp"
#include "fixity.hpp"
#include "isolated_worker.hpp"
#include "ivol/error.hpp"
#include "ivol/metadata.hpp"
#include "option_parsing.hpp"
#include "signal_cleanup.hpp"

namespace {

int run(int argc, char** argv) {
  using namespace ivol::cli;
  CLI::App app{"ivol — archival storage of CT volumes with inhomogeneous resolution (.ivol files)"};
  app.require_subcommand(1);
  app.fallthrough();  // -q and -v also after the subcommand
  app.set_version_flag("--version", std::string("ivol ") + ivol::library_version());
  GlobalOptions global;
  global.command_line = quoted_command_line(argc, argv);
  app.add_flag("-q,--quiet", global.quiet, "Print nothing but errors");
  app.add_flag("-v,--verbose", global.verbose, "Print more detail");

  std::map<CLI::App*, Runner> runners;
  auto add = [&](Runner (*adder)(CLI::App&, const GlobalOptions&)) {
    const std::size_t before = app.get_subcommands({}).size();
    Runner run = adder(app, global);
    runners[app.get_subcommands({})[before]] = std::move(run);
  };
  add(add_demo_command);
  add(add_info_command);
  add(add_verify_command);
  add(add_convert_command);
  add(add_extract_command);
  add(add_slice_command);
  add(add_phantom_command);
  add(add_devices_command);
  add(add_recon_command);

  if (argc > 1 && argv[1][0] != '-') {
    bool known = false;
    for (auto& [sub, run] : runners) known = known || sub->get_name() == argv[1];
    if (!known) {
      std::cerr << "ivol: unknown command '" << argv[1] << "' (see ivol --help)\n";
      return kExitUsage;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);  // help goes to stdout, exit 0
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e, std::cerr, std::cerr);
    return kExitUsage;
  }
  for (auto& [sub, run] : runners) {
    if (!sub->parsed()) continue;
    try {
      return run();
    } catch (const UsageError& e) {
      std::cerr << "ivol " << sub->get_name() << ": " << e.what() << "\n";
      return kExitUsage;
    } catch (const ivol::Error& e) {
      std::cerr << "ivol " << sub->get_name() << ": error (" << ivol::error_class_name(e.error_class())
                << "): " << e.what() << "\n";
      return kExitFailure;
    } catch (const std::bad_alloc&) {
      // A last resort: sizes are weighed before they are allocated
      // (tools/convert/sizes.hpp), so this is an allocation nobody foresaw.
      std::cerr << "ivol " << sub->get_name() << ": error (" << ivol::error_class_name(ivol::ErrorClass::LimitExceeded)
                << "): out of memory: an allocation failed while running the command"
                << (sub->get_option_no_throw("--memory") ? "; --memory may bound it" : "") << "\n";
      return kExitFailure;
    } catch (const std::system_error& e) {
      // Threads that cannot start (EAGAIN): an address-space or process
      // limit. Work that can run on fewer threads does; this is what cannot.
      const bool limit = e.code() == std::errc::resource_unavailable_try_again;
      std::cerr << "ivol " << sub->get_name() << ": error ("
                << ivol::error_class_name(limit ? ivol::ErrorClass::LimitExceeded : ivol::ErrorClass::Io)
                << "): " << (limit ? "a thread could not be started (an address-space or process limit): " : "")
                << e.what() << "\n";
      return kExitFailure;
    } catch (const std::length_error& e) {
      // The same for a size past what a container can hold at all.
      std::cerr << "ivol " << sub->get_name() << ": error (" << ivol::error_class_name(ivol::ErrorClass::LimitExceeded)
                << "): a size past what can be allocated (" << e.what() << ")\n";
      return kExitFailure;
    } catch (const std::exception& e) {
      std::cerr << "ivol " << sub->get_name() << ": error: " << e.what() << "\n";
      return kExitFailure;
    }
  }
  return kExitUsage;
}

}  // namespace

int main(int argc, char** argv) {
  // Started again as the child that runs libhdf5 (isolated_worker.hpp):
  // serves its parent and exits here.
  ivol::convert::serve_if_worker_process();
  // Before any thread exists, so that every thread inherits the blocked signals.
  ivol::cli::start_signal_cleanup();
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "ivol: error: " << e.what() << "\n";
    return ivol::cli::kExitFailure;
  }
}
