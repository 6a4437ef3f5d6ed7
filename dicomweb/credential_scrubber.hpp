#pragma once
// Keeps a source's credentials out of every message this library makes. A PACS (or a proxy in
// front of it) may echo the request's Authorization header back anywhere it writes text: an
// error body, a Content-Type, a multipart part's headers, a redirect. Each DicomWebError leaves
// HttpClient and Client through scrubbingErrors(), so no message that quotes what a PACS sent
// can carry the credentials out, whichever code built it.
//
// The forms kept out, each also percent-encoded (any mix of upper- and lower-case hex, '+' for
// a space): the whole Authorization value ("Basic dXNlcjpwYXNz"), its credentials alone
// ("dXNlcjpwYXNz"), and for Basic the decoded "user:pass" and the password alone. Any run of
// 8 or more characters of one of these is cut out too (all of a shorter one), so that a quote
// cut short for length cannot show the start of a credential.

#include "dicomweb/errors.hpp"

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace volcast::dicomweb {

class CredentialScrubber {
  public:
    static constexpr std::string_view kReplacement = "[credentials]";
    // Messages are cut to this many bytes: each quote of a PACS is shorter, this bounds the whole.
    static constexpr size_t kMaxMessageBytes = 2000;

    explicit CredentialScrubber(const std::string &authorization);

    // `text` without any form of the credentials, control characters as spaces, cut to
    // kMaxMessageBytes (on a UTF-8 character boundary, "..." marking the cut).
    std::string operator()(std::string_view text) const;

    // `text` without any form of the credentials, nothing else changed.
    std::string withoutCredentials(std::string_view text) const;

    // The forms kept out, longest first (tests).
    const std::vector<std::string> &secrets() const { return secrets_; }

  private:
    std::vector<std::string> secrets_;
};

// Runs `call`; a DicomWebError coming out of it comes out with its message scrubbed, its kind
// kept.
template <class Call> decltype(auto) scrubbingErrors(const CredentialScrubber &scrubber, Call &&call) {
    try {
        return call();
    } catch (const DicomWebError &e) {
        throw DicomWebError(e.kind, scrubber(e.what()));
    }
}

} // namespace volcast::dicomweb
