#include "server/upload_ids.hpp"

#include <openssl/evp.h>

#include <algorithm>
#include <stdexcept>

namespace volcast::server {

namespace {

constexpr size_t kIdHexDigits = 32;   // upload_store.cpp's ids: 128 bits
constexpr size_t kShownHexDigits = 8;

bool isLowerHex(char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); }

} // namespace

std::string sha256Hex(std::string_view text) {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    if (EVP_Digest(text.data(), text.size(), digest, &length, EVP_sha256(), nullptr) != 1)
        throw std::runtime_error("SHA-256 failed (OpenSSL's EVP_Digest)");
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out;
    for (unsigned int i = 0; i < length; ++i) {
        out += kHex[digest[i] >> 4];
        out += kHex[digest[i] & 15];
    }
    return out;
}

std::string uploadFolderName(std::string_view id) { return sha256Hex(id); }

std::string hideUploadIds(std::string_view text) {
    std::string out;
    size_t i = 0;
    while (i < text.size()) {
        size_t run = 0;
        while (i + run < text.size() && isLowerHex(text[i + run])) ++run;
        if (run == kIdHexDigits) {
            out += '#';
            out += sha256Hex(text.substr(i, run)).substr(0, kShownHexDigits);
        } else {
            out += text.substr(i, std::max<size_t>(run, 1));
        }
        i += std::max<size_t>(run, 1);
    }
    return out;
}

} // namespace volcast::server
