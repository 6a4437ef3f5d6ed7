// A binary frame message as a client decodes it (decodeFrame). Invariants: only DecodeError
// escapes; the image span lies inside the message; a decoded frame re-encodes (encodeFrame)
// to a message that decodes to the same header and image bytes.

#include "fuzz/fuzz_check.hpp"
#include "protocol/frame.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

using namespace volcast;
using namespace volcast::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::span<const uint8_t> message(data, size);
    DecodedFrame frame;
    try {
        frame = decodeFrame(message);
    } catch (const DecodeError &) {
        return 0;
    }
    fuzz::check(frame.image.empty() ||
                    (frame.image.data() >= data && frame.image.data() + frame.image.size() <= data + size),
                "the decoded image span points outside the message");
    std::vector<uint8_t> again;
    try {
        again = encodeFrame(frame.header, frame.image);
    } catch (const std::exception &e) {
        fuzz::fail("a decoded frame header does not encode again", e.what());
    }
    DecodedFrame back;
    try {
        back = decodeFrame(again);
    } catch (const DecodeError &e) {
        fuzz::fail("a re-encoded frame does not decode", e.what());
    }
    fuzz::check(back.header == frame.header, "a re-encoded frame decodes to a different header");
    fuzz::check(std::equal(back.image.begin(), back.image.end(), frame.image.begin(), frame.image.end()),
                "a re-encoded frame decodes to different image bytes");
    // Re-encoding is canonical: encoding the decoded copy gives the same bytes again.
    fuzz::check(encodeFrame(back.header, back.image) == again, "frame encoding is not stable");
    return 0;
}
