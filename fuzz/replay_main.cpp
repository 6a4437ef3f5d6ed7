// A main() for a fuzz target in the normal g++ build: feeds each input file once to the
// target's LLVMFuzzerTestOneInput, as libFuzzer does with -runs=0, without libFuzzer or
// clang. Used by the `fuzz_corpus.*` tests, which replay the committed corpora (seeds and
// regression inputs) with the target's invariants checked (README.md here).
//
//   fuzz_corpus_TARGET FILE_OR_FOLDER...      every regular file, each folder's in name order
//
// A broken invariant aborts (fuzz_check.hpp); the input's name is printed before it runs, so
// the failure names it.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
// Defined by the targets that set something up before the first input (fuzz_volume_header).
extern "C" __attribute__((weak)) int LLVMFuzzerInitialize(int *argc, char ***argv);

namespace fs = std::filesystem;

int main(int argc, char **argv) {
    if (LLVMFuzzerInitialize) LLVMFuzzerInitialize(&argc, &argv);
    std::vector<fs::path> inputs;
    for (int i = 1; i < argc; ++i) {
        const fs::path arg = argv[i];
        if (fs::is_directory(arg)) {
            std::vector<fs::path> files;
            for (const auto &e : fs::directory_iterator(arg))
                if (e.is_regular_file()) files.push_back(e.path());
            std::sort(files.begin(), files.end());
            inputs.insert(inputs.end(), files.begin(), files.end());
        } else if (fs::is_regular_file(arg)) {
            inputs.push_back(arg);
        } else {
            std::fprintf(stderr, "no such file or folder: %s\n", arg.c_str());
            return 2;
        }
    }
    if (inputs.empty()) {
        std::fprintf(stderr, "no inputs to replay (usage: %s FILE_OR_FOLDER...)\n", argv[0]);
        return 2;
    }
    for (const fs::path &input : inputs) {
        std::ifstream in(input, std::ios::binary);
        if (!in) {
            std::fprintf(stderr, "cannot open %s\n", input.c_str());
            return 2;
        }
        const std::vector<char> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        std::fprintf(stderr, "input %s (%zu bytes)\n", input.c_str(), bytes.size());
        std::fflush(stderr);
        // A copy of exactly the input's size, as libFuzzer passes it: a read past the end is
        // past the allocation.
        const std::vector<uint8_t> data(bytes.begin(), bytes.end());
        LLVMFuzzerTestOneInput(data.empty() ? nullptr : data.data(), data.size());
    }
    std::printf("%zu inputs replayed, every invariant held\n", inputs.size());
    return 0;
}
