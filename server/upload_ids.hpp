#pragma once
// An upload's id (upload_store.hpp) is the only key to it: the logs and the upload folder's
// file names show a SHA-256 of it instead. A hash, not the id cut short, because 8 digits of
// the id would be 32 of its 128 bits given away; 8 hex digits of its SHA-256 give away
// nothing that helps to find it (2^96 ids share them), and still tell uploads apart in a log.
// The whole digest (64 hex digits) names its folder on disk, so that no path a loader logs
// holds the id either; a digest cannot be turned back into a random 128-bit id.

#include <string>
#include <string_view>

namespace volcast::server {

// The SHA-256 of `text` as 64 lowercase hex digits.
std::string sha256Hex(std::string_view text);

// The name of an upload's folder: sha256Hex(id).
std::string uploadFolderName(std::string_view id);

// `text` with every upload id in it (a run of exactly 32 lowercase hex digits) replaced by
// "#" and the first 8 hex digits of its SHA-256: "upload:3f…" becomes "upload:#1a2b3c4d".
// Every log line that may print a volume name, or a message that may hold one, goes
// through this.
std::string hideUploadIds(std::string_view text);

} // namespace volcast::server
