#pragma once
// The OpenCL context the OpenCL tests share (kept apart from test_scenes.hpp, so that the
// model's tests, which link no OpenCL, can use the scene pieces).

#include "renderer/opencl/opencl_context.hpp"

#include <memory>

namespace volcast::test {

// One OpenCL context for every test file: each new feature set costs PoCL about a second to
// build, and the program cache lives in the context.
inline const std::shared_ptr<OpenClContext> &sharedOpenClContext() {
    static const auto cl = std::make_shared<OpenClContext>();
    return cl;
}

} // namespace volcast::test
