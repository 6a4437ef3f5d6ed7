// A server text message as a client decodes it (parseServerMessage, used by the C++ client
// and mirrored by the Python and browser clients). Invariants: only DecodeError escapes;
// a decoded message re-encodes (toJsonText) to valid UTF-8 that decodes to an equal message.

#include "fuzz/fuzz_check.hpp"
#include "protocol/server_messages.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

using namespace volcast;
using namespace volcast::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string_view text(reinterpret_cast<const char *>(data), size);
    ServerMessage message;
    try {
        message = parseServerMessage(text);
    } catch (const DecodeError &) {
        return 0;
    }
    std::string again;
    try {
        again = toJsonText(message);
    } catch (const std::exception &e) {
        fuzz::fail("a decoded server message does not serialise", e.what());
    }
    fuzz::check(fuzz::isValidUtf8(again), "a re-encoded server message is not valid UTF-8", again);
    ServerMessage back;
    try {
        back = parseServerMessage(again);
    } catch (const DecodeError &e) {
        fuzz::fail("a re-encoded server message does not decode", std::string(e.what()) + "\n  text: " + again);
    }
    fuzz::check(back == message, "a re-encoded server message decodes different", again);
    return 0;
}
