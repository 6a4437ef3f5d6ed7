// OpenClContext's program cache: a program is reused only for the same source and the same
// build options, never for another source that happens to share the options.

#include "renderer/opencl/opencl_context.hpp"
#include "opencl_test_context.hpp"
#include "test_scenes.hpp"

#include <gtest/gtest.h>

#include <string>

namespace volcast {
namespace {

// Runs the one-int kernel `name` of `program` and returns what it wrote (-1, with the reason,
// when the program has no such kernel).
int runKernel(OpenClContext &cl, const cl::Program &program, const char *name) {
    cl::Kernel kernel;
    try {
        kernel = cl::Kernel(program, name);
    } catch (const cl::Error &e) {
        ADD_FAILURE() << "the program has no kernel '" << name << "' (" << e.what() << " returned " << e.err()
                      << "): the cache returned a program built from another source";
        return -1;
    }
    cl::Buffer out(cl.context(), CL_MEM_WRITE_ONLY, sizeof(cl_int));
    kernel.setArg(0, out);
    cl.queue().enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(1));
    cl_int value = 0;
    cl.queue().enqueueReadBuffer(out, CL_TRUE, 0, sizeof value, &value);
    return value;
}

TEST(OpenClProgramCache, TwoSourcesWithTheSameOptionsAreTwoPrograms) {
    OpenClContext &cl = *test::sharedOpenClContext();
    // Options no other test uses, so the cache holds neither program yet.
    const std::string options = "-DVOLCAST_PROGRAM_CACHE_TEST=1";
    const std::string first = "kernel void first(global int *out) { out[0] = 1; }";
    const std::string second = "kernel void second(global int *out) { out[0] = 2; }";
    const auto a = cl.program(first, options);
    const auto b = cl.program(second, options);
    EXPECT_EQ(runKernel(cl, a.program, "first"), 1);
    // A cache keyed on the options alone hands back `first`, which has no kernel "second".
    EXPECT_EQ(runKernel(cl, b.program, "second"), 2);
}

TEST(OpenClProgramCache, TheSameSourceAndOptionsAreBuiltOnce) {
    OpenClContext &cl = *test::sharedOpenClContext();
    const std::string options = "-DVOLCAST_PROGRAM_CACHE_TEST=2";
    const std::string source = "kernel void once(global int *out) { out[0] = 3; }";
    const size_t before = cl.programsBuilt();
    const auto a = cl.program(source, options);
    const auto b = cl.program(source, options);
    EXPECT_EQ(cl.programsBuilt(), before + 1);
    EXPECT_EQ(b.buildSeconds, 0.0) << "the second request must come from the cache";
    EXPECT_EQ(runKernel(cl, b.program, "once"), 3);
    (void)a;
}

} // namespace
} // namespace volcast
