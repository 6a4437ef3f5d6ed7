// One DICOM slice's header as the direct reader of uncompressed series parses it
// (renderer/io/dicom_uncompressed.hpp, parseUncompressedSlice): the file's bytes as they are.
// The parse runs in the checker process, but a parser that reads past its buffer or loops
// would still cost every DICOM load; AddressSanitizer watches the first, libFuzzer's timeout
// the second.
// Invariants: a refusal says why, in printable ASCII; an accepted slice has pixels of 8 or
// 16 bits with its stored bits the low ones, at least one row and column, its pixel data
// starting inside the bytes given, finite geometry, an integer intercept within 2^20, and a
// CT or MR SOP class; the same bytes give the same answer twice.

#include "renderer/io/dicom_uncompressed.hpp"

#include "fuzz/fuzz_check.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

using namespace volcast;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::span<const unsigned char> bytes(data, size);
    std::string why;
    const auto slice = io::parseUncompressedSlice(bytes, why);
    std::string again;
    const auto twice = io::parseUncompressedSlice(bytes, again);
    fuzz::check(bool(slice) == bool(twice) && why == again, "the same bytes parse differently twice");
    if (!slice) {
        fuzz::check(!why.empty(), "a refusal without a reason");
        for (char c : why) fuzz::check(c >= 0x20 && c < 0x7f, "a refusal's reason is not printable ASCII", why);
        return 0;
    }
    fuzz::check(slice->rows >= 1 && slice->columns >= 1 && slice->rows <= 65535 && slice->columns <= 65535,
                "rows or columns out of range");
    fuzz::check(slice->bitsAllocated == 8 || slice->bitsAllocated == 16, "pixels neither 8 nor 16 bits");
    fuzz::check(slice->bitsStored >= 1 && slice->bitsStored <= slice->bitsAllocated, "stored bits out of range");
    fuzz::check(slice->pixelOffset <= size, "pixel data starts past the bytes given");
    for (double x : {slice->position.x, slice->position.y, slice->position.z, slice->pixelSpacing[0],
                     slice->pixelSpacing[1]})
        fuzz::check(std::isfinite(x), "non-finite position or spacing");
    for (double x : slice->orientation) fuzz::check(std::isfinite(x), "non-finite orientation");
    fuzz::check(slice->intercept == std::trunc(slice->intercept) && std::abs(slice->intercept) <= 1048576,
                "intercept not an integer within 2^20");
    fuzz::check(slice->sopClass == "1.2.840.10008.5.1.4.1.1.2" || slice->sopClass == "1.2.840.10008.5.1.4.1.1.4",
                "a SOP class other than CT or MR Image Storage");
    return 0;
}
