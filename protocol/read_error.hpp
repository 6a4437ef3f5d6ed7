#pragma once
// Internal to protocol/: the protocol's side of reading JSON. Fields, kinds and paths are
// read by the shared json_fields library (util/README.md); here are the errors that
// carry a protocol error code (ReadError), how a json_fields::FieldError becomes one, and
// the request id. The public parse functions catch both once and answer with a
// ProtocolError carrying the request's id.

#include "util/json_fields.hpp"
#include "protocol/errors.hpp"

#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>

namespace volcast::protocol::detail {

using json = nlohmann::json;
using json_fields::element;
using json_fields::FieldError;
using json_fields::Fields;
using json_fields::kMaxQuotedBytes;
using json_fields::member;
using json_fields::parseText;
using json_fields::ParsedText;
using json_fields::kindOf;
using json_fields::object;
using json_fields::array;
using json_fields::string;
using json_fields::boolean;
using json_fields::number;
using json_fields::integer;
using json_fields::unsignedInteger;
using json_fields::badField;

struct ReadError : std::runtime_error {
    ReadError(ErrorCode c, const std::string &message) : std::runtime_error(message), code(c) {}
    ErrorCode code;
};

[[noreturn]] void fail(ErrorCode code, const std::string &message);

// A field error as the protocol words it: malformed_json, too_large or bad_field, and a
// path of the client's keys quoted by its start (a 60 KiB key is not echoed whole).
ErrorCode codeOf(const FieldError &e);
std::string messageOf(const FieldError &e);

// A request id: null, an integer, or a string of at most maxBytes bytes.
json requestId(const json &j, const std::string &path, size_t maxBytes);

} // namespace volcast::protocol::detail
