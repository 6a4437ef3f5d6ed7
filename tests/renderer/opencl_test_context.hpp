#pragma once
// The OpenCL context the OpenCL tests share (kept apart from test_scenes.hpp, so that the
// model's tests, which link no OpenCL, can use the scene pieces).

#include "renderer/opencl/opencl_context.hpp"

namespace volcast::test {

// One OpenCL context for every test file: each new feature set costs PoCL about a second to
// build, and the program cache lives in the context.
inline OpenClContext &sharedOpenClContext() {
    static OpenClContext cl;
    return cl;
}

} // namespace volcast::test
