# Writes a C++ file defining the string constant NAME: the FILES (a list, concatenated in
# order, e.g. a shared header then the .cl file), so a program builds from memory with no
# include path. Run at build time.
set(source "")
foreach(file IN LISTS FILES)
  file(READ "${file}" text)
  string(APPEND source "${text}\n")
endforeach()
file(WRITE "${OUT}" "// Generated from renderer/opencl/kernels by embed.cmake; do not edit.
#include \"renderer/opencl/embedded_kernels.hpp\"
namespace volcast {
const char *const ${NAME} = R\"volcast_cl(#define VOLCAST_EMBEDDED 1
${source})volcast_cl\";
}
")
