#pragma once
// The protocol quotes client text through json_fields' UTF-8 helpers (util/utf8.hpp),
// under the protocol's own names.

#include "util/utf8.hpp"

namespace volcast::protocol {
using json_fields::isValidUtf8;
using json_fields::quotableText;
} // namespace volcast::protocol
