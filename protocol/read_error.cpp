#include "protocol/read_error.hpp"

#include "protocol/utf8.hpp"

namespace volcast::protocol::detail {

void fail(ErrorCode code, const std::string &message) { throw ReadError(code, message); }

ErrorCode codeOf(const FieldError &e) {
    switch (e.kind) {
    case FieldError::Kind::Malformed: return ErrorCode::MalformedJson;
    case FieldError::Kind::TooDeep: return ErrorCode::TooLarge;
    case FieldError::Kind::BadField: break;
    }
    return ErrorCode::BadField;
}

std::string messageOf(const FieldError &e) {
    return e.path.empty() ? e.problem : quotableText(e.path, kMaxQuotedBytes) + ": " + e.problem;
}

json requestId(const json &j, const std::string &path, size_t maxBytes) {
    if (j.is_null() || j.is_number_integer()) return j;
    if (j.is_string()) {
        string(j, path, maxBytes);
        return j;
    }
    badField(path, "must be an integer or a string, got " + kindOf(j));
}

} // namespace volcast::protocol::detail
