// ivol devices [--json]: the OpenCL devices `ivol recon` can use, numbered as
// its --device option numbers them.
#include <iostream>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "ivol/recon/fdk.hpp"
#include "report.hpp"

namespace ivol::cli {

Runner add_devices_command(CLI::App& app, const GlobalOptions& /*global*/) {
  auto* cmd = app.add_subcommand("devices", "List the OpenCL devices reconstruction can run on");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "Print one JSON object (for machines)");
  return [json]() {
    const std::vector<recon::DeviceInfo> devices = recon::list_devices();
    if (*json) {
      nlohmann::json list = nlohmann::json::array();
      for (const recon::DeviceInfo& d : devices)
        list.push_back({{"index", d.index},
                        {"name", d.name},
                        {"platform", d.platform},
                        {"version", d.version},
                        {"type", d.is_gpu ? "gpu" : "cpu"},
                        {"global_memory_bytes", d.global_memory},
                        {"max_allocation_bytes", d.max_allocation},
                        {"local_memory_bytes", d.local_memory},
                        {"compute_units", d.compute_units}});
      std::cout << nlohmann::json{{"devices", list}}.dump(2) << "\n";
    } else {
      for (const recon::DeviceInfo& d : devices)
        std::cout << d.index << "  " << d.name << " (" << (d.is_gpu ? "GPU" : "CPU") << ")\n"
                  << "   platform       " << d.platform << ", " << d.version << "\n"
                  << "   memory         " << human_bytes(d.global_memory) << " global, "
                  << human_bytes(d.max_allocation) << " largest allocation, " << human_bytes(d.local_memory)
                  << " local\n"
                  << "   compute units  " << d.compute_units << "\n";
    }
    if (devices.empty()) {
      std::cerr << "ivol devices: no OpenCL device found; install an OpenCL driver (for the CPU on Debian or "
                   "Ubuntu: apt install pocl-opencl-icd; for a GPU: its vendor's OpenCL driver)\n";
      return kExitFailure;
    }
    return kExitOk;
  };
}

}  // namespace ivol::cli
