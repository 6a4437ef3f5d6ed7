// A slice message (VCS1) as a client decodes it (decodeSlice). Invariants: only DecodeError
// escapes; the pixel span lies inside the message and holds width x height bytes; a decoded
// slice re-encodes (encodeSlice) to a message that decodes to the same header and pixels.
// The slice request itself is read by parseClientMessage, which fuzz_client_message covers.

#include "fuzz/fuzz_check.hpp"
#include "protocol/slice.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

using namespace volcast;
using namespace volcast::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::span<const uint8_t> message(data, size);
    DecodedSlice slice;
    try {
        slice = decodeSlice(message);
    } catch (const DecodeError &) {
        return 0;
    }
    fuzz::check(slice.pixels.data() >= data && slice.pixels.data() + slice.pixels.size() <= data + size,
                "the decoded pixel span points outside the message");
    fuzz::check(slice.pixels.size() == size_t(slice.header.width) * size_t(slice.header.height),
                "the decoded pixels are not width x height bytes");
    std::vector<uint8_t> again;
    try {
        again = encodeSlice(slice.header, slice.pixels);
    } catch (const std::exception &e) {
        fuzz::fail("a decoded slice header does not encode again", e.what());
    }
    DecodedSlice back;
    try {
        back = decodeSlice(again);
    } catch (const DecodeError &e) {
        fuzz::fail("a re-encoded slice does not decode", e.what());
    }
    fuzz::check(back.header == slice.header, "a re-encoded slice decodes to a different header");
    fuzz::check(std::equal(back.pixels.begin(), back.pixels.end(), slice.pixels.begin(), slice.pixels.end()),
                "a re-encoded slice decodes to different pixels");
    return 0;
}
