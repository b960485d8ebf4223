#include "opencl_runtime.hpp"

#include <stdexcept>

namespace ivol::recon::detail {

const char* embedded_recon_kernels();  // generated from kernels/*.cl

namespace {

const char* status_name(cl_int status) {
  switch (status) {
    case CL_DEVICE_NOT_FOUND:
      return "CL_DEVICE_NOT_FOUND";
    case CL_DEVICE_NOT_AVAILABLE:
      return "CL_DEVICE_NOT_AVAILABLE";
    case CL_MEM_OBJECT_ALLOCATION_FAILURE:
      return "CL_MEM_OBJECT_ALLOCATION_FAILURE";
    case CL_OUT_OF_RESOURCES:
      return "CL_OUT_OF_RESOURCES";
    case CL_OUT_OF_HOST_MEMORY:
      return "CL_OUT_OF_HOST_MEMORY";
    case CL_BUILD_PROGRAM_FAILURE:
      return "CL_BUILD_PROGRAM_FAILURE";
    case CL_INVALID_VALUE:
      return "CL_INVALID_VALUE";
    case CL_INVALID_BUFFER_SIZE:
      return "CL_INVALID_BUFFER_SIZE";
    case CL_INVALID_KERNEL_ARGS:
      return "CL_INVALID_KERNEL_ARGS";
    case CL_INVALID_WORK_GROUP_SIZE:
      return "CL_INVALID_WORK_GROUP_SIZE";
    case CL_INVALID_WORK_ITEM_SIZE:
      return "CL_INVALID_WORK_ITEM_SIZE";
    case CL_INVALID_GLOBAL_WORK_SIZE:
      return "CL_INVALID_GLOBAL_WORK_SIZE";
    case CL_INVALID_ARG_SIZE:
      return "CL_INVALID_ARG_SIZE";
    case CL_INVALID_PLATFORM:
      return "CL_INVALID_PLATFORM";
    case -1001:
      return "CL_PLATFORM_NOT_FOUND_KHR (no OpenCL platform is installed)";
    default:
      return "OpenCL error";
  }
}

}  // namespace

std::string describe(const cl::Error& error) {
  return std::string(error.what()) + " failed: " + status_name(error.err()) + " (" + std::to_string(error.err()) + ")";
}

std::vector<DeviceHandle> enumerate_devices() {
  std::vector<DeviceHandle> handles;
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error& error) {
    if (error.err() == -1001) return handles;  // no ICD installed: no devices
    throw std::runtime_error("OpenCL: " + describe(error));
  }
  for (const cl::Platform& platform : platforms) {
    std::vector<cl::Device> devices;
    try {
      platform.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;  // a platform without devices
    }
    for (const cl::Device& device : devices) {
      DeviceHandle h{device, platform, {}};
      h.info.index = static_cast<int>(handles.size());
      h.info.name = device.getInfo<CL_DEVICE_NAME>();
      h.info.platform = platform.getInfo<CL_PLATFORM_NAME>();
      h.info.version = device.getInfo<CL_DEVICE_VERSION>();
      h.info.is_gpu = (device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) != 0;
      h.info.global_memory = device.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
      h.info.max_allocation = device.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
      h.info.local_memory = device.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>();
      h.info.compute_units = device.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
      // Trim the trailing NULs some drivers leave in strings.
      for (std::string* s : {&h.info.name, &h.info.platform, &h.info.version})
        while (!s->empty() && s->back() == '\0') s->pop_back();
      handles.push_back(std::move(h));
    }
  }
  return handles;
}

std::vector<DeviceHandle> choose_devices(const std::vector<int>& wanted) {
  std::vector<DeviceHandle> all = enumerate_devices();
  if (all.empty())
    throw std::runtime_error(
        "OpenCL: no device found; install an OpenCL driver (on Debian: pocl-opencl-icd for the CPU)");
  std::vector<DeviceHandle> chosen;
  if (!wanted.empty()) {
    for (int index : wanted) {
      if (index < 0 || index >= static_cast<int>(all.size()))
        throw std::invalid_argument("OpenCL: device " + std::to_string(index) + " does not exist; there are " +
                                    std::to_string(all.size()) + " (see `ivol devices`)");
      chosen.push_back(all[static_cast<std::size_t>(index)]);
    }
    return chosen;
  }
  for (const DeviceHandle& h : all)
    if (h.info.is_gpu) chosen.push_back(h);
  if (chosen.empty()) chosen.push_back(all.front());
  return chosen;
}

std::string recon_program_source() { return embedded_recon_kernels(); }

cl::Program build_recon_program(const cl::Context& context, const cl::Device& device, const std::string& options) {
  cl::Program program(context, recon_program_source());
  try {
    program.build(std::vector<cl::Device>{device}, ("-cl-std=CL1.2 " + options).c_str());
  } catch (const cl::Error& error) {
    std::string log;
    try {
      log = program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device);
    } catch (const cl::Error&) {
    }
    throw std::runtime_error("OpenCL: building the recon kernels for " + device.getInfo<CL_DEVICE_NAME>() +
                             " failed: " + describe(error) + "\n" + log);
  }
  return program;
}

}  // namespace ivol::recon::detail

namespace ivol::recon {

std::vector<DeviceInfo> list_devices() {
  std::vector<DeviceInfo> infos;
  for (const detail::DeviceHandle& h : detail::enumerate_devices()) infos.push_back(h.info);
  return infos;
}

}  // namespace ivol::recon

namespace ivol::recon::detail {

std::vector<int> probe_device_layout(const DeviceHandle& handle) {
  cl::Context context(handle.device);
  cl::CommandQueue queue(context, handle.device);
  cl::Program program = build_recon_program(context, handle.device, "");
  cl::Kernel kernel(program, "layout_probe");
  std::vector<int> values(28, -1);
  cl::Buffer out(context, CL_MEM_WRITE_ONLY, values.size() * sizeof(int));
  kernel.setArg(0, out);
  queue.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(1), cl::NullRange);
  queue.enqueueReadBuffer(out, CL_TRUE, 0, values.size() * sizeof(int), values.data());
  return values;
}

}  // namespace ivol::recon::detail
