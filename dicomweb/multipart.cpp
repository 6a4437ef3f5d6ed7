#include "dicomweb/multipart.hpp"

#include <algorithm>
#include <cctype>

namespace volcast::dicomweb {

namespace {

char lower(char c) { return char(std::tolower(static_cast<unsigned char>(c))); }

bool equalsIgnoringCase(std::string_view a, std::string_view b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) { return lower(x) == lower(y); });
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
    return s;
}

// RFC 2045 token characters.
bool isTokenChar(char c) {
    const auto u = static_cast<unsigned char>(c);
    if (u <= 0x20 || u >= 0x7f) return false;
    return std::string_view("()<>@,;:\\\"/[]?=").find(c) == std::string_view::npos;
}

// For messages: the offending bytes, printable and short.
std::string quoted(std::string_view s) {
    std::string out = "'";
    for (char c : s.substr(0, 40)) {
        const auto u = static_cast<unsigned char>(c);
        out += (u >= 0x20 && u < 0x7f) ? c : '?';
    }
    return out + (s.size() > 40 ? "...'" : "'");
}

constexpr size_t kMaxPadding = 1024;  // spaces and tabs after a delimiter

} // namespace

std::string MultipartHeaders::get(std::string_view name) const {
    for (const auto &[key, value] : fields)
        if (equalsIgnoringCase(key, name)) return value;
    return {};
}

std::string ContentType::parameter(std::string_view name) const {
    for (const auto &[key, value] : parameters)
        if (key == name) return value;
    return {};
}

ContentType parseContentType(std::string_view value) {
    ContentType out;
    size_t i = std::min(value.find(';'), value.size());
    const std::string_view media = trim(value.substr(0, i));
    const size_t slash = media.find('/');
    if (slash == std::string_view::npos || slash == 0 || slash + 1 == media.size() ||
        !std::all_of(media.begin(), media.end(), [](char c) { return c == '/' || isTokenChar(c); }) ||
        media.find('/', slash + 1) != std::string_view::npos)
        throw MultipartError("content type " + quoted(value) + " has no type/subtype");
    for (char c : media) out.mediaType += lower(c);
    auto skipSpace = [&] {
        while (i < value.size() && (value[i] == ' ' || value[i] == '\t')) ++i;
    };
    // Here value[i] is the ';' before a parameter, or i is the end.
    while (i < value.size()) {
        ++i;
        skipSpace();
        if (i >= value.size()) break;
        if (value[i] == ';') continue;
        const size_t eq = std::min(value.find('=', i), value.size());
        const size_t semicolon = std::min(value.find(';', i), value.size());
        if (eq == value.size() || semicolon < eq)
            throw MultipartError("content type parameter " + quoted(value.substr(i)) + " has no '='");
        const std::string_view nameView = trim(value.substr(i, eq - i));
        if (nameView.empty() || !std::all_of(nameView.begin(), nameView.end(), isTokenChar))
            throw MultipartError("content type parameter name " + quoted(nameView) + " is not a token");
        std::string name;
        for (char c : nameView) name += lower(c);
        i = eq + 1;
        skipSpace();
        std::string parameterValue;
        if (i < value.size() && value[i] == '"') {
            ++i;
            bool closedQuote = false;
            while (i < value.size()) {
                const char c = value[i++];
                if (c == '"') {
                    closedQuote = true;
                    break;
                }
                // A quoted pair: the backslash escapes the next character.
                parameterValue += (c == '\\' && i < value.size()) ? value[i++] : c;
            }
            if (!closedQuote) throw MultipartError("content type parameter " + name + " has an unterminated quoted value");
            skipSpace();
            if (i < value.size() && value[i] != ';')
                throw MultipartError("content type parameter " + name + " has text after its quoted value");
        } else {
            const size_t end = std::min(value.find(';', i), value.size());
            parameterValue = std::string(trim(value.substr(i, end - i)));
            i = end;
        }
        out.parameters.emplace_back(std::move(name), std::move(parameterValue));
    }
    return out;
}

std::string multipartBoundary(std::string_view contentTypeValue) {
    const ContentType type = parseContentType(contentTypeValue);
    if (type.mediaType.rfind("multipart/", 0) != 0)
        throw MultipartError("content type " + quoted(type.mediaType) + " is not multipart");
    bool present = false;
    for (const auto &p : type.parameters) present = present || p.first == "boundary";
    if (!present) throw MultipartError("multipart content type has no boundary parameter");
    const std::string boundary = type.parameter("boundary");
    if (boundary.empty() || boundary.size() > 70)
        throw MultipartError("multipart boundary must be 1 to 70 characters, not " + std::to_string(boundary.size()));
    static constexpr std::string_view kSpecials = "'()+_,-./:=? ";
    for (char c : boundary)
        if (!std::isalnum(static_cast<unsigned char>(c)) && kSpecials.find(c) == std::string_view::npos)
            throw MultipartError("multipart boundary " + quoted(boundary) + " holds a character RFC 2046 does not allow");
    if (boundary.back() == ' ') throw MultipartError("multipart boundary ends in a space");
    return boundary;
}

MultipartReader::MultipartReader(std::string boundary, Callbacks callbacks, MultipartLimits limits)
    : boundary_(std::move(boundary)), delimiter_("\r\n--" + boundary_), callbacks_(std::move(callbacks)),
      limits_(limits) {
    if (boundary_.empty() || boundary_.size() > 70)
        throw MultipartError("multipart boundary must be 1 to 70 characters, not " + std::to_string(boundary_.size()));
    // The body may begin with its first delimiter, without the CRLF before it: a CRLF of our
    // own in front makes that the same search as everywhere else.
    buffer_ = "\r\n";
}

std::string MultipartReader::partName() const { return "part " + std::to_string(partsBegun_); }

void MultipartReader::fail(const std::string &what) {
    state_ = State::Failed;
    throw MultipartError(what);
}

void MultipartReader::feed(std::string_view chunk) {
    if (state_ == State::Failed) throw MultipartError("multipart body fed after an earlier error");
    if (state_ == State::Epilogue) return;  // the epilogue is ignored
    buffer_.append(chunk);
    try {
        run();
    } catch (...) {
        state_ = State::Failed;
        throw;
    }
}

void MultipartReader::run() {
    for (;;) {
        bool progressed = false;
        switch (state_) {
        case State::Preamble: progressed = stepPreamble(); break;
        case State::AfterDelimiter: progressed = stepAfterDelimiter(); break;
        case State::Headers: progressed = stepHeaders(); break;
        case State::Data: progressed = stepData(); break;
        case State::Epilogue: buffer_.clear(); return;
        case State::Failed: return;
        }
        if (!progressed) return;
    }
}

bool MultipartReader::stepPreamble() {
    const size_t at = buffer_.find(delimiter_);
    if (at != std::string::npos) {
        preambleBytes_ += at;
        if (preambleBytes_ > limits_.maxPreambleBytes + 2)  // 2: the CRLF put in front
            fail("multipart body has no delimiter in its first " + std::to_string(limits_.maxPreambleBytes) + " bytes");
        buffer_.erase(0, at + delimiter_.size());
        state_ = State::AfterDelimiter;
        return true;
    }
    const size_t keep = delimiter_.size() - 1;
    if (buffer_.size() > keep) {
        preambleBytes_ += buffer_.size() - keep;
        buffer_.erase(0, buffer_.size() - keep);
    }
    if (preambleBytes_ > limits_.maxPreambleBytes + 2)
        fail("multipart body has no delimiter in its first " + std::to_string(limits_.maxPreambleBytes) + " bytes");
    return false;
}

bool MultipartReader::stepAfterDelimiter() {
    size_t i = 0;
    if (buffer_.empty() || (buffer_.size() == 1 && buffer_[0] == '-')) return false;
    if (buffer_[0] == '-' && buffer_[1] == '-') {
        state_ = State::Epilogue;
        buffer_.clear();
        return true;
    }
    while (i < buffer_.size() && (buffer_[i] == ' ' || buffer_[i] == '\t')) ++i;
    if (i > kMaxPadding) fail("multipart delimiter after " + partName() + " is followed by too much padding");
    if (i == buffer_.size()) return false;
    size_t lineEnd = 0;
    if (buffer_[i] == '\n') {
        lineEnd = i + 1;
    } else if (buffer_[i] == '\r') {
        if (i + 1 == buffer_.size()) return false;
        if (buffer_[i + 1] != '\n') fail("multipart delimiter after " + partName() + " is followed by a lone CR");
        lineEnd = i + 2;
    } else {
        fail("multipart delimiter after " + partName() + " is followed by " + quoted(buffer_.substr(i, 16)) +
             ", not a line end or '--'");
    }
    if (partsBegun_ >= limits_.maxParts)
        fail("multipart body has more than " + std::to_string(limits_.maxParts) + " parts");
    buffer_.erase(0, lineEnd);
    ++partsBegun_;
    partBytes_ = 0;
    scanned_ = 0;
    state_ = State::Headers;
    return true;
}

bool MultipartReader::stepHeaders() {
    // Lines end in LF (a CR before it is dropped); an empty line ends the block. scanned_ is
    // where the current, incomplete line begins: every line before it was complete and not
    // empty, so each byte is searched once however small the chunks.
    for (size_t nl = buffer_.find('\n', scanned_); nl != std::string::npos; nl = buffer_.find('\n', scanned_)) {
        std::string_view line(buffer_.data() + scanned_, nl - scanned_);
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (!line.empty()) {
            scanned_ = nl + 1;
            if (scanned_ > limits_.maxHeaderBytes)
                fail("the headers of " + partName() + " are longer than " + std::to_string(limits_.maxHeaderBytes) + " bytes");
            continue;
        }
        MultipartHeaders headers;
        std::string_view block(buffer_.data(), scanned_);
        while (!block.empty()) {
            const size_t end = block.find('\n');
            std::string_view text = block.substr(0, end);
            block.remove_prefix(end + 1);
            if (!text.empty() && text.back() == '\r') text.remove_suffix(1);
            if (!text.empty() && (text.front() == ' ' || text.front() == '\t')) {
                if (headers.fields.empty()) fail("the headers of " + partName() + " begin with a continuation line");
                headers.fields.back().second += " ";
                headers.fields.back().second += trim(text);
                continue;
            }
            const size_t colon = text.find(':');
            const std::string_view name = colon == std::string_view::npos ? std::string_view{} : text.substr(0, colon);
            if (name.empty() || !std::all_of(name.begin(), name.end(), isTokenChar))
                fail("header line " + quoted(text) + " of " + partName() + " is not 'Name: value'");
            headers.fields.emplace_back(std::string(name), std::string(trim(text.substr(colon + 1))));
        }
        buffer_.erase(0, nl + 1);
        scanned_ = 0;
        state_ = State::Data;
        if (callbacks_.partBegin) callbacks_.partBegin(headers);
        return true;
    }
    // The incomplete line will make the block too long unless it is the CR of the blank line
    // that ends it (that line does not count): the same verdict however the body is chunked.
    const bool maybeBlankLine = buffer_.size() == scanned_ + 1 && buffer_.back() == '\r';
    if (buffer_.size() > limits_.maxHeaderBytes && !maybeBlankLine)
        fail("the headers of " + partName() + " are longer than " + std::to_string(limits_.maxHeaderBytes) + " bytes");
    return false;
}

bool MultipartReader::stepData() {
    const size_t at = buffer_.find(delimiter_);
    const size_t keep = delimiter_.size() - 1;
    const size_t emit = at != std::string::npos ? at : (buffer_.size() > keep ? buffer_.size() - keep : 0);
    if (emit > 0) {
        partBytes_ += emit;
        if (partBytes_ > limits_.maxPartBytes)
            fail(partName() + " is larger than " + std::to_string(limits_.maxPartBytes) + " bytes");
        if (callbacks_.partData) callbacks_.partData(std::string_view(buffer_.data(), emit));
    }
    if (at == std::string::npos) {
        buffer_.erase(0, emit);
        return false;
    }
    buffer_.erase(0, at + delimiter_.size());
    ++partsEnded_;
    state_ = State::AfterDelimiter;
    if (callbacks_.partEnd) callbacks_.partEnd();
    return true;
}

void MultipartReader::finish() {
    switch (state_) {
    case State::Epilogue: return;
    case State::Failed: throw MultipartError("multipart body was refused earlier");
    case State::Preamble: throw MultipartError("multipart body ended before its first delimiter (no part)");
    case State::AfterDelimiter:
        throw MultipartError("multipart body ended after " + (partsEnded_ ? partName() : std::string("its first delimiter")) +
                             " without its closing delimiter");
    case State::Headers: throw MultipartError("multipart body ended inside the headers of " + partName());
    case State::Data:
        throw MultipartError("multipart body ended inside " + partName() + " (cut short, no closing delimiter)");
    }
}

} // namespace volcast::dicomweb
