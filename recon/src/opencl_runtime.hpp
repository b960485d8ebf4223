// The OpenCL side of recon: finding devices, building the kernels (embedded
// in the library at build time from kernels/*.cl) and turning OpenCL status
// codes into messages.
#pragma once

#define CL_HPP_TARGET_OPENCL_VERSION 120
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#define CL_HPP_ENABLE_EXCEPTIONS
#include <CL/opencl.hpp>
#include <string>
#include <vector>

#include "ivol/recon/fdk.hpp"

namespace ivol::recon::detail {

struct DeviceHandle {
  cl::Device device;
  cl::Platform platform;
  DeviceInfo info;
};

// Every OpenCL device of every platform, GPUs and CPUs, numbered as
// list_devices() numbers them.
std::vector<DeviceHandle> enumerate_devices();

// The devices FdkOptions::devices names, or the default choice.
std::vector<DeviceHandle> choose_devices(const std::vector<int>& wanted);

// Kernel sources, in build order: the shared layout header first.
std::string recon_program_source();

// Builds the recon program for one device; `options` are extra compiler
// flags. Throws std::runtime_error with the build log on failure.
cl::Program build_recon_program(const cl::Context& context, const cl::Device& device, const std::string& options);

// "clEnqueueNDRangeKernel failed: CL_OUT_OF_RESOURCES (-5)".
std::string describe(const cl::Error& error);

}  // namespace ivol::recon::detail

namespace ivol::recon::detail {
// The device compiler's sizes and offsets of the shared layouts
// (kernels/recon_layout.h), read back by the layout_probe kernel.
std::vector<int> probe_device_layout(const DeviceHandle& device);
}  // namespace ivol::recon::detail
