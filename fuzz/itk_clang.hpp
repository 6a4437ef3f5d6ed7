#pragma once
// Forced into renderer/io/volume_io.cpp in the fuzz build only (fuzz/CMakeLists.txt). Debian's
// ITK 5.2 headers were generated for g++ alone: itk_compiler_detection.h stops with
// "Unsupported compiler" for clang. Including it once here, with clang presenting itself as
// the g++ 12 those headers were made for, lets its include guard keep the later includes
// quiet. The feature macros it defines (alignas, noexcept, ...) are all ones clang 14 has.
#pragma push_macro("__clang__")
#pragma push_macro("__GNUC__")
#pragma push_macro("__GNUC_MINOR__")
#undef __clang__
#undef __GNUC__
#undef __GNUC_MINOR__
#define __GNUC__ 12
#define __GNUC_MINOR__ 2
#include <itk_compiler_detection.h>
#pragma pop_macro("__GNUC_MINOR__")
#pragma pop_macro("__GNUC__")
#pragma pop_macro("__clang__")
