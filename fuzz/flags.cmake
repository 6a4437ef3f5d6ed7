# Included by the top-level CMakeLists before the libraries when VOLCAST_FUZZ is on: every
# object in this build tree, the libraries the targets link included, gets coverage
# instrumentation for libFuzzer and the address and undefined-behaviour sanitizers.
# UBSan findings abort (no recovery), so libFuzzer records them like any crash.
if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
  message(FATAL_ERROR "VOLCAST_FUZZ needs clang (libFuzzer); configure a separate build folder with "
                      "-DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14")
endif()
set(VOLCAST_SANITIZERS -fsanitize=address,undefined -fno-sanitize-recover=undefined)
add_compile_options(-fsanitize=fuzzer-no-link ${VOLCAST_SANITIZERS} -fno-omit-frame-pointer -g)
# Executables outside fuzz/ (volcast-server, volcast-render) still link in this tree.
add_link_options(${VOLCAST_SANITIZERS})
