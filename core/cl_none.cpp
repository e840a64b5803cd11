// The device half of the runtime in a build without OpenCL (BTFC_OPENCL=OFF, or no OpenCL
// headers at configure time): no OpenCL header, no library, every device call an error that
// says so. `auto` then warns once and runs the C++ references; `cl` fails with this message.
#include "core/cl_runtime.h"

namespace btfc::ocl {
namespace {

Status not_built() {
  return Status(StatusCode::device_error,
                "built without OpenCL (configured with BTFC_OPENCL=OFF or without OpenCL headers; "
                "reconfigure with -DBTFC_OPENCL=ON after apt-get install opencl-headers)");
}

}  // namespace

bool built_with_opencl() { return false; }
bool library_loaded() { return false; }
Result<std::vector<DeviceInfo>> list_devices() { return not_built(); }
Result<Runtime*> Runtime::create() { return not_built(); }
Result<Kernel> Runtime::kernel(const std::string&, const std::string&) { return not_built(); }
Status Kernel::raw_arg(int, size_t, const void*) { return not_built(); }
Status Kernel::arg(int, int32_t) { return not_built(); }
Status Kernel::arg(int, float) { return not_built(); }
Status Kernel::arg(int, const Buffer&) { return not_built(); }
Status Kernel::launch(int, const size_t*, const size_t*, const char*) const { return not_built(); }
Result<Buffer> Buffer::create(Runtime&, size_t, const void*, Access) { return not_built(); }
Result<Buffer> Buffer::wrap(Runtime&, size_t, void*, Access) { return not_built(); }
Status Buffer::sync_to_host(size_t) const { return not_built(); }
void Buffer::reset() { m_mem = nullptr; }  // never holds a buffer here

}  // namespace btfc::ocl
