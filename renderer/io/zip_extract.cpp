#include "renderer/io/zip_extract.hpp"

#include <spdlog/fmt/fmt.h>
#include <zip.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <memory>
#include <string>

namespace volcast {

namespace fs = std::filesystem;

bool isZipName(const fs::path &path) {
    std::string name = path.filename().string();
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return name.size() > 4 && name.ends_with(".zip");
}

namespace {

struct ArchiveCloser {
    void operator()(zip_t *z) const { zip_discard(z); }
};
struct EntryCloser {
    void operator()(zip_file_t *f) const { zip_fclose(f); }
};
struct Fd {
    int fd = -1;
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
};

std::string libzipMessage(int code) {
    zip_error_t error;
    zip_error_init_with_code(&error, code);
    std::string text = zip_error_strerror(&error);
    zip_error_fini(&error);
    return text;
}

} // namespace

int64_t extractZip(const fs::path &archive, const fs::path &folder, const ZipLimits &limits,
                   const std::string &displayName) {
    const auto refuse = [&](const std::string &problem) -> ZipError {
        return ZipError(displayName + ": " + problem);
    };
    std::error_code ec;
    const uint64_t archiveBytes = fs::file_size(archive, ec);
    if (ec) throw refuse("cannot be read: " + ec.message());
    int code = 0;
    // ZIP_CHECKCONS: the central directory must agree with the local headers (libzip's
    // consistency checks), the usual sign of a damaged or crafted archive.
    std::unique_ptr<zip_t, ArchiveCloser> zip(zip_open(archive.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &code));
    if (!zip) throw refuse("is not a valid zip archive (libzip: " + libzipMessage(code) + ")");
    const zip_int64_t count = zip_get_num_entries(zip.get(), 0);
    if (count < 0) throw refuse("is not a valid zip archive (no central directory)");
    if (count > limits.maxEntries)
        throw refuse(fmt::format("holds {} entries, more than the limit of {}", count, limits.maxEntries));
    // Bytes allowed out: the limit, and no more than the ratio allows (1 MiB of slack for tiny archives).
    const uint64_t ratioBound = uint64_t(limits.maxRatio * double(archiveBytes)) + (uint64_t(1) << 20);
    const uint64_t bound = std::min(limits.maxBytes, ratioBound);

    uint64_t declared = 0, written = 0;
    int64_t entries = 0;
    std::array<char, 64 * 1024> buffer;
    for (zip_int64_t i = 0; i < count; ++i) {
        zip_stat_t st;
        zip_stat_init(&st);
        if (zip_stat_index(zip.get(), zip_uint64_t(i), 0, &st) != 0)
            throw refuse(fmt::format("entry {} cannot be read: {}", i, zip_strerror(zip.get())));
        const std::string name = (st.valid & ZIP_STAT_NAME) && st.name ? st.name : "";
        if (name.ends_with('/')) continue;   // a folder: its files come as entries of their own
        zip_uint8_t opsys = 0;
        zip_uint32_t attributes = 0;
        if (zip_file_get_external_attributes(zip.get(), zip_uint64_t(i), 0, &opsys, &attributes) == 0 &&
            opsys == ZIP_OPSYS_UNIX) {
            const mode_t mode = mode_t(attributes >> 16);
            if (S_ISDIR(mode)) continue;
            // No file-type bits at all (Python's zipfile.writestr writes just 0600) is a
            // regular file; a type that is not a regular file is a link or a device.
            if ((mode & S_IFMT) != 0 && !S_ISREG(mode))
                throw refuse(fmt::format("entry {} is a symbolic link or special file, not a regular file", i));
        }
        if ((st.valid & ZIP_STAT_ENCRYPTION_METHOD) && st.encryption_method != ZIP_EM_NONE)
            throw refuse(fmt::format("entry {} is encrypted", i));
        if (!(st.valid & ZIP_STAT_SIZE)) throw refuse(fmt::format("entry {} has no size", i));
        declared += st.size;
        if (declared > limits.maxBytes)
            throw refuse(fmt::format("unpacks to more than the limit of {} MiB", limits.maxBytes >> 20));
        if (declared > ratioBound)
            throw refuse(fmt::format("unpacks to more than {:g} times its own size (a zip bomb)", limits.maxRatio));
        if (!zip_compression_method_supported(st.valid & ZIP_STAT_COMP_METHOD ? st.comp_method : ZIP_CM_STORE, 0))
            throw refuse(fmt::format("entry {} uses a compression method this server cannot read", i));

        std::unique_ptr<zip_file_t, EntryCloser> in(zip_fopen_index(zip.get(), zip_uint64_t(i), 0));
        if (!in) throw refuse(fmt::format("entry {} cannot be opened: {}", i, zip_strerror(zip.get())));
        const fs::path out = folder / fmt::format("entry_{:05d}", entries);
        Fd fd{::open(out.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600)};
        if (fd.fd < 0) throw refuse(fmt::format("cannot be unpacked: {}", std::strerror(errno)));
        uint64_t entryBytes = 0;
        for (;;) {
            const zip_int64_t n = zip_fread(in.get(), buffer.data(), buffer.size());
            if (n < 0) throw refuse(fmt::format("entry {} is damaged: {}", i, zip_file_strerror(in.get())));
            if (n == 0) break;
            entryBytes += uint64_t(n);
            written += uint64_t(n);
            // libzip checks each entry against its declared size and CRC; this holds the
            // bound even if it did not.
            if (entryBytes > st.size || written > bound)
                throw refuse(fmt::format("entry {} unpacks to more bytes than it declares", i));
            for (zip_int64_t done = 0; done < n;) {
                const ssize_t w = ::write(fd.fd, buffer.data() + done, size_t(n - done));
                if (w < 0) {
                    if (errno == EINTR) continue;
                    throw refuse(fmt::format("cannot be unpacked: {}", std::strerror(errno)));
                }
                done += w;
            }
        }
        if (entryBytes != st.size) throw refuse(fmt::format("entry {} is shorter than it declares", i));
        ++entries;
    }
    if (entries == 0) throw refuse("holds no files");
    return entries;
}

} // namespace volcast
