// A WebSocket text message from a client, as the server handles it: parseClientMessage,
// then the answer the server would send. Invariants:
// - parseClientMessage never throws (its contract);
// - an error answer serialises (toJsonText) to valid UTF-8 JSON that a client reads back
//   as the same code, and the message is never empty;
// - an accepted message re-encodes (toJsonText) to text that parses back to an equal one.

#include "fuzz/fuzz_check.hpp"
#include "protocol/client_messages.hpp"
#include "protocol/server_messages.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <variant>

using namespace volcast;
using namespace volcast::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string_view text(reinterpret_cast<const char *>(data), size);
    const ParsedClientMessage parsed = parseClientMessage(text);

    if (const auto *error = std::get_if<ProtocolError>(&parsed)) {
        fuzz::check(!error->message.empty(), "an error answer has an empty message");
        // What WebsocketSession sends; nlohmann's dump throws type_error 316 on bad UTF-8.
        std::string answer;
        try {
            answer = toJsonText(ServerMessage{*error});
        } catch (const std::exception &e) {
            fuzz::fail("serialising the error answer threw", e.what());
        }
        fuzz::check(fuzz::isValidUtf8(answer), "the error answer is not valid UTF-8", answer);
        ServerMessage back;
        try {
            back = parseServerMessage(answer);
        } catch (const std::exception &e) {
            fuzz::fail("a client cannot read the error answer back", e.what());
        }
        const auto *backError = std::get_if<ProtocolError>(&back);
        fuzz::check(backError && backError->code == error->code && backError->message == error->message &&
                        backError->requestId == error->requestId,
                    "the error answer reads back different", answer);
        return 0;
    }

    const ClientMessage &message = std::get<ClientMessage>(parsed);
    const std::string again = toJsonText(message);
    const ParsedClientMessage reparsed = parseClientMessage(again);
    const auto *same = std::get_if<ClientMessage>(&reparsed);
    fuzz::check(same != nullptr, "an accepted message, re-encoded, is refused", again);
    fuzz::check(*same == message, "an accepted message, re-encoded, reads back different", again);
    return 0;
}
