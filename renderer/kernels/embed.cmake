# Writes a C++ file holding the ray-casting kernel source: the shared header, then the .cl
# file, so the program builds from memory with no include path. Run at build time.
file(READ "${SHARED}" shared)
file(READ "${KERNEL}" kernel)
file(WRITE "${OUT}" "// Generated from renderer/kernels by embed.cmake; do not edit.
#include \"renderer/embedded_kernels.hpp\"
namespace volcast {
const char *const kRaycastKernelSource = R\"volcast_cl(#define VOLCAST_EMBEDDED 1
${shared}
${kernel})volcast_cl\";
}
")
