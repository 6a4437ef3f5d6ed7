#include "dicomweb/dicomweb_client.hpp"

#include "dicomweb/http_client.hpp"
#include "dicomweb/multipart.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>

namespace volcast::dicomweb {

using nlohmann::json;

namespace {

constexpr const char *kJson = "application/dicom+json";
constexpr const char *kMultipartDicom = "multipart/related; type=\"application/dicom\"";
// Attribute values from a PACS are cut to this many bytes: they end up in messages and web pages.
constexpr size_t kMaxAttributeBytes = 256;
// JSON nesting a DICOM JSON answer needs: array, dataset, attribute, Value, PN object (and
// sequences, which are not read). Deeper is refused before parsing.
constexpr int kMaxJsonDepth = 32;

// ---- query values --------------------------------------------------------------------

bool validUtf8(std::string_view s) {
    size_t i = 0;
    while (i < s.size()) {
        const auto c = static_cast<unsigned char>(s[i]);
        size_t extra = 0;
        uint32_t cp = 0;
        if (c < 0x80) {
            ++i;
            continue;
        } else if ((c & 0xE0) == 0xC0) {
            extra = 1;
            cp = c & 0x1Fu;
        } else if ((c & 0xF0) == 0xE0) {
            extra = 2;
            cp = c & 0x0Fu;
        } else if ((c & 0xF8) == 0xF0) {
            extra = 3;
            cp = c & 0x07u;
        } else {
            return false;
        }
        if (i + extra >= s.size()) return false;
        for (size_t k = 1; k <= extra; ++k) {
            const auto d = static_cast<unsigned char>(s[i + k]);
            if ((d & 0xC0) != 0x80) return false;
            cp = (cp << 6) | (d & 0x3Fu);
        }
        static constexpr uint32_t kMin[] = {0, 0x80, 0x800, 0x10000};
        if (cp < kMin[extra] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
        i += extra + 1;
    }
    return true;
}

void checkText(std::string_view field, const std::string &value, size_t maxBytes) {
    if (value.size() > maxBytes)
        throw DicomWebError(ErrorKind::BadQuery, "filter " + std::string(field) + " is longer than " +
                                                     std::to_string(maxBytes) + " bytes");
    for (char c : value) {
        const auto u = static_cast<unsigned char>(c);
        if (u < 0x20 || u == 0x7f)
            throw DicomWebError(ErrorKind::BadQuery, "filter " + std::string(field) + " holds a control character");
        if (c == '\\')
            throw DicomWebError(ErrorKind::BadQuery,
                                "filter " + std::string(field) + " holds a backslash (DICOM's value separator)");
    }
    if (!validUtf8(value))
        throw DicomWebError(ErrorKind::BadQuery, "filter " + std::string(field) + " is not valid UTF-8");
}

bool validDate(std::string_view d) {
    if (d.size() != 8 || !std::all_of(d.begin(), d.end(), [](char c) { return c >= '0' && c <= '9'; })) return false;
    const int month = (d[4] - '0') * 10 + (d[5] - '0');
    const int day = (d[6] - '0') * 10 + (d[7] - '0');
    return month >= 1 && month <= 12 && day >= 1 && day <= 31;
}

void checkDate(const std::string &value) {
    const auto bad = [&] {
        return DicomWebError(ErrorKind::BadQuery, "filter study_date must be YYYYMMDD or a range YYYYMMDD-YYYYMMDD "
                                                  "(either end may be empty), not '" +
                                                      (value.size() <= 17 && validUtf8(value) &&
                                                               std::none_of(value.begin(), value.end(),
                                                                            [](char c) { return static_cast<unsigned char>(c) < 0x20; })
                                                           ? value
                                                           : std::string("...")) +
                                                      "'");
    };
    const size_t dash = value.find('-');
    if (dash == std::string::npos) {
        if (!validDate(value)) throw bad();
        return;
    }
    const std::string_view from = std::string_view(value).substr(0, dash);
    const std::string_view to = std::string_view(value).substr(dash + 1);
    if ((from.empty() && to.empty()) || (!from.empty() && !validDate(from)) || (!to.empty() && !validDate(to)))
        throw bad();
    if (!from.empty() && !to.empty() && from > to)
        throw DicomWebError(ErrorKind::BadQuery, "filter study_date range ends before it begins");
}

// A query value with only what must be escaped escaped: RFC 3986 allows sub-delimiters, ':',
// '@', '/' and '?' in a query, and '^' (PersonName's separator) passes every HTTP stack we
// know. Orthanc 1.10's DICOMweb plugin does not percent-decode QIDO values, so the wildcards
// '*' and '?' and the '^' must go as they are to match there; '&', '=', '+', '#', '%', white
// space and bytes outside ASCII are escaped (and then match nothing on such a server).
std::string percentEncoded(std::string_view s) {
    static constexpr char kHex[] = "0123456789ABCDEF";
    static constexpr std::string_view kAsIs = "-._~!$'()*,;:@/?^";
    std::string out;
    for (char c : s) {
        const auto u = static_cast<unsigned char>(c);
        if (u < 0x80 && (std::isalnum(u) || kAsIs.find(c) != std::string_view::npos)) {
            out += c;
        } else {
            out += '%';
            out += kHex[u >> 4];
            out += kHex[u & 15];
        }
    }
    return out;
}

// ---- DICOM JSON, read defensively ------------------------------------------------------

// Cut to kMaxAttributeBytes on a character boundary, control characters as spaces.
std::string cleanText(std::string s) {
    if (s.size() > kMaxAttributeBytes) {
        size_t cut = kMaxAttributeBytes;
        while (cut > 0 && (static_cast<unsigned char>(s[cut]) & 0xC0) == 0x80) --cut;
        s.resize(cut);
    }
    for (char &c : s)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
    while (!s.empty() && s.back() == ' ') s.pop_back();  // DICOM pads to even length
    return s;
}

const json *firstValue(const json &dataset, const char *tag) {
    if (!dataset.is_object()) return nullptr;
    const auto attribute = dataset.find(tag);
    if (attribute == dataset.end() || !attribute->is_object()) return nullptr;
    const auto values = attribute->find("Value");
    if (values == attribute->end() || !values->is_array() || values->empty()) return nullptr;
    return &(*values)[0];
}

std::string stringOf(const json &dataset, const char *tag) {
    const json *v = firstValue(dataset, tag);
    if (!v) return {};
    if (v->is_string()) return cleanText(v->get<std::string>());
    if (v->is_number_integer()) return std::to_string(v->get<int64_t>());
    return {};
}

// A UI value: a JSON string that is a UID, else "" (a number is not taken as a UID).
std::string uidOf(const json &dataset, const char *tag) {
    const json *v = firstValue(dataset, tag);
    if (!v || !v->is_string()) return {};
    std::string uid = v->get<std::string>();
    while (!uid.empty() && (uid.back() == ' ' || uid.back() == '\0')) uid.pop_back();  // DICOM's padding
    return isUid(uid) ? uid : std::string();
}

// PersonName: the Alphabetic component group (Ideographic and Phonetic are not shown).
std::string personNameOf(const json &dataset, const char *tag) {
    const json *v = firstValue(dataset, tag);
    if (!v) return {};
    if (v->is_object()) {
        const auto alphabetic = v->find("Alphabetic");
        if (alphabetic != v->end() && alphabetic->is_string()) return cleanText(alphabetic->get<std::string>());
        return {};
    }
    if (v->is_string()) return cleanText(v->get<std::string>());  // some servers send PN as text
    return {};
}

std::vector<std::string> stringsOf(const json &dataset, const char *tag) {
    std::vector<std::string> out;
    if (!firstValue(dataset, tag)) return out;
    for (const json &v : dataset.at(tag).at("Value"))
        if (v.is_string() && out.size() < 64) out.push_back(cleanText(v.get<std::string>()));
    return out;
}

// IS and US values: a JSON integer, a whole float, or a decimal string (some servers send IS
// as text). nullopt when missing or not a whole number in range.
std::optional<int64_t> integerOf(const json &dataset, const char *tag) {
    const json *v = firstValue(dataset, tag);
    if (!v) return std::nullopt;
    if (v->is_number_unsigned()) {
        const uint64_t u = v->get<uint64_t>();
        if (u > uint64_t(std::numeric_limits<int64_t>::max())) return std::nullopt;
        return int64_t(u);
    }
    if (v->is_number_integer()) return v->get<int64_t>();
    if (v->is_number_float()) {
        const double d = v->get<double>();
        if (!std::isfinite(d) || d != std::floor(d) || std::fabs(d) > 9e15) return std::nullopt;
        return int64_t(d);
    }
    if (v->is_string()) {
        std::string_view s = v->get_ref<const std::string &>();
        while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
        while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
        if (!s.empty() && s.front() == '+') s.remove_prefix(1);
        int64_t out = 0;
        const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
        if (ec != std::errc() || end != s.data() + s.size() || s.empty()) return std::nullopt;
        return out;
    }
    return std::nullopt;
}

// Nesting depth of a JSON text, strings skipped, so that a hostile answer of a million '['
// never reaches the parser.
bool nestingWithin(std::string_view text, int limit) {
    int depth = 0;
    bool inString = false;
    for (size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (inString) {
            if (c == '\\') ++i;
            else if (c == '"') inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '[' || c == '{') {
            if (++depth > limit) return false;
        } else if (c == ']' || c == '}') {
            --depth;
        }
    }
    return true;
}

std::string sourceText(const SourceConfig &config) { return "DICOMweb source '" + config.name + "'"; }

// A QIDO-RS answer: a JSON array of datasets. 204 and an empty body are no match.
json parseDatasets(const SourceConfig &config, const CredentialScrubber &scrubber, const HttpResponse &response,
                   const std::string &url) {
    const std::string what = sourceText(config) + " answered GET " + HttpClient::pathForMessage(url);
    if (response.status == 204 || response.body.empty()) return json::array();
    std::string media;
    try {
        media = parseContentType(response.contentType).mediaType;
    } catch (const MultipartError &) {
    }
    if (media != "application/dicom+json" && media != "application/json")
        throw DicomWebError(ErrorKind::BadResponse,
                            what + " with Content-Type '" + cleanText(scrubber.withoutCredentials(response.contentType)) +
                                "', not application/dicom+json");
    if (!nestingWithin(response.body, kMaxJsonDepth))
        throw DicomWebError(ErrorKind::BadResponse, what + " with JSON nested deeper than " + std::to_string(kMaxJsonDepth));
    json parsed = json::parse(response.body, nullptr, false);
    if (parsed.is_discarded()) throw DicomWebError(ErrorKind::BadResponse, what + " with malformed JSON");
    if (!parsed.is_array()) throw DicomWebError(ErrorKind::BadResponse, what + " with JSON that is not an array");
    return parsed;
}

HttpOptions httpOptions(const SourceConfig &config, bool retrieval) {
    HttpOptions o;
    o.sourceName = config.name;
    o.authorization = config.authorization;
    o.connectTimeoutSeconds = config.connectTimeoutSeconds;
    // Retrieval of a large series may take long: only a stalled transfer ends it.
    o.requestTimeoutSeconds = retrieval ? 0 : config.requestTimeoutSeconds;
    o.lowSpeedSeconds = config.lowSpeedSeconds;
    return o;
}

void checkUids(const SourceConfig &config, const std::string &studyUid, const std::string &seriesUid) {
    for (const auto &[name, uid] : {std::pair{"study", &studyUid}, std::pair{"series", &seriesUid}})
        if (!isUid(*uid))
            throw DicomWebError(ErrorKind::BadQuery, sourceText(config) + ": the " + std::string(name) +
                                                         " UID is not a DICOM UID (digits and dots, at most 64)");
}

// An instance file being written: created fresh (never through a link), closed on scope exit.
class InstanceFile {
  public:
    explicit InstanceFile(const std::filesystem::path &path) : path_(path) {
        fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_NOFOLLOW | O_CLOEXEC, 0600);
        if (fd_ < 0) throw error("could not be created");
    }
    ~InstanceFile() {
        if (fd_ >= 0) ::close(fd_);
    }
    InstanceFile(const InstanceFile &) = delete;
    InstanceFile &operator=(const InstanceFile &) = delete;
    void write(std::string_view data) {
        while (!data.empty()) {
            const ssize_t n = ::write(fd_, data.data(), data.size());
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) throw error("could not be written");
            data.remove_prefix(size_t(n));
        }
    }
    void close() {
        const int fd = fd_;
        fd_ = -1;
        if (::close(fd) != 0) throw error("could not be closed");
    }

  private:
    DicomWebError error(const std::string &what) const {
        return DicomWebError(ErrorKind::Storage, path_.string() + " " + what + ": " + std::strerror(errno));
    }
    std::filesystem::path path_;
    int fd_ = -1;
};

} // namespace

bool isUid(std::string_view text) {
    if (text.empty() || text.size() > 64 || text.front() == '.' || text.back() == '.') return false;
    for (size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (c == '.') {
            if (text[i - 1] == '.') return false;
        } else if (c < '0' || c > '9') {
            return false;
        }
    }
    return true;
}

std::string studyQueryString(const StudyQuery &query) {
    if (query.limit < 1 || query.limit > 1000)
        throw DicomWebError(ErrorKind::BadQuery, "limit must be 1 to 1000, not " + std::to_string(query.limit));
    checkText("patient_name", query.patientName, 64);
    checkText("patient_id", query.patientId, 64);
    checkText("accession_number", query.accessionNumber, 16);
    checkText("modality", query.modality, 16);
    if (!std::all_of(query.modality.begin(), query.modality.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == ' '; }))
        throw DicomWebError(ErrorKind::BadQuery, "filter modality may hold only letters, digits, '_' and spaces");
    if (!query.studyDate.empty()) checkDate(query.studyDate);

    std::string out;
    const auto add = [&](const char *key, const std::string &value) {
        if (value.empty()) return;
        out += key;
        out += '=';
        out += percentEncoded(value);
        out += '&';
    };
    add("PatientName", query.patientName);
    add("PatientID", query.patientId);
    add("StudyDate", query.studyDate);
    add("ModalitiesInStudy", query.modality);
    add("AccessionNumber", query.accessionNumber);
    out += "limit=" + std::to_string(query.limit) + "&includefield=00081030&includefield=00080061";
    return out;
}

Client::Client(SourceConfig config) : config_(std::move(config)), scrubber_(config_.authorization) {
    const std::string &url = config_.baseUrl;
    std::string lowered;
    for (char c : url.substr(0, 8)) lowered += char(std::tolower(static_cast<unsigned char>(c)));
    const size_t schemeEnd = lowered.rfind("http://", 0) == 0 ? 7 : lowered.rfind("https://", 0) == 0 ? 8 : 0;
    if (schemeEnd == 0)
        throw DicomWebError(ErrorKind::BadQuery, sourceText(config_) + ": the base URL must begin with http:// or https://");
    const std::string authority = url.substr(schemeEnd, url.find('/', schemeEnd) - schemeEnd);
    if (authority.empty())
        throw DicomWebError(ErrorKind::BadQuery, sourceText(config_) + ": the base URL has no host");
    if (authority.find('@') != std::string::npos)
        throw DicomWebError(ErrorKind::BadQuery, sourceText(config_) +
                                                     ": the base URL holds credentials; give them as an Authorization value instead");
    if (url.find_first_of("?# \t\r\n") != std::string::npos)
        throw DicomWebError(ErrorKind::BadQuery,
                            sourceText(config_) + ": the base URL may hold no query, fragment or white space");
    if (config_.authorization.find_first_of("\r\n") != std::string::npos)
        throw DicomWebError(ErrorKind::BadQuery,
                            sourceText(config_) + ": the Authorization value holds a line break (it must be one line)");
    base_ = url;
    while (!base_.empty() && base_.back() == '/') base_.pop_back();
}

std::vector<StudyRecord> Client::findStudies(const StudyQuery &query) {
    return scrubbingErrors(scrubber_, [&] { return searchStudies(query); });
}

SeriesSize Client::seriesSize(const std::string &studyUid, const std::string &seriesUid) {
    return scrubbingErrors(scrubber_, [&] { return measureSeries(studyUid, seriesUid); });
}

RetrieveProgress Client::retrieveSeries(const std::string &studyUid, const std::string &seriesUid,
                                        const std::filesystem::path &folder, uint64_t maxBytes,
                                        const std::function<void(const RetrieveProgress &)> &progress,
                                        const std::function<bool()> &cancelled, int64_t expectedInstances) {
    return scrubbingErrors(scrubber_, [&] {
        return retrieve(studyUid, seriesUid, folder, maxBytes, progress, cancelled, expectedInstances);
    });
}

std::vector<StudyRecord> Client::searchStudies(const StudyQuery &query) {
    const std::string url = base_ + "/studies?" + studyQueryString(query);
    HttpClient http(httpOptions(config_, false));
    const json studies = parseDatasets(config_, scrubber_, http.get(url, kJson, config_.maxQueryBytes), url);

    std::vector<StudyRecord> out;
    size_t skipped = 0;
    for (const json &dataset : studies) {
        if (out.size() >= size_t(query.limit)) break;  // a server that ignores limit
        StudyRecord study;
        study.studyUid = uidOf(dataset, "0020000D");
        if (!isUid(study.studyUid)) {
            ++skipped;
            continue;
        }
        study.patientName = personNameOf(dataset, "00100010");
        study.patientId = stringOf(dataset, "00100020");
        study.studyDate = stringOf(dataset, "00080020");
        study.description = stringOf(dataset, "00081030");
        study.accessionNumber = stringOf(dataset, "00080050");
        study.modalities = stringsOf(dataset, "00080061");
        out.push_back(std::move(study));
    }
    if (skipped > 0) spdlog::warn("{}: {} studies without a valid Study Instance UID left out", sourceText(config_), skipped);

    for (StudyRecord &study : out) {
        const std::string seriesUrl =
            base_ + "/studies/" + study.studyUid + "/series?includefield=0008103E&includefield=00201209";
        json series;
        try {
            series = parseDatasets(config_, scrubber_, http.get(seriesUrl, kJson, config_.maxQueryBytes), seriesUrl);
        } catch (const DicomWebError &e) {
            if (e.kind != ErrorKind::NotFound) throw;
            continue;  // the study went away between the two requests
        }
        for (const json &dataset : series) {
            SeriesRecord record;
            record.seriesUid = uidOf(dataset, "0020000E");
            if (!isUid(record.seriesUid)) continue;
            record.modality = stringOf(dataset, "00080060");
            record.description = stringOf(dataset, "0008103E");
            record.instances = std::max<int64_t>(0, integerOf(dataset, "00201209").value_or(0));
            study.series.push_back(std::move(record));
        }
    }
    spdlog::debug("{}: {} studies found", sourceText(config_), out.size());
    return out;
}

SeriesSize Client::measureSeries(const std::string &studyUid, const std::string &seriesUid) {
    checkUids(config_, studyUid, seriesUid);
    HttpClient http(httpOptions(config_, false));
    // The size of one image from the first instance's record, the count from the series' own
    // (Number of Series Related Instances): asking every instance for its Rows and Columns made
    // Orthanc open all 300 files of a CT series (0.17-0.3 s) before retrieval could begin. A
    // series whose images differ in size stays bounded all the same: retrieval stops at its
    // byte limit, and the loader checks every slice. A source that does not give the count is
    // asked for every instance's record.
    const std::string seriesUrl = base_ + "/studies/" + studyUid + "/series?SeriesInstanceUID=" + seriesUid +
                                  "&includefield=00201209";
    const json series = parseDatasets(config_, scrubber_, http.get(seriesUrl, kJson, config_.maxQueryBytes), seriesUrl);
    std::optional<int64_t> count;
    for (const json &dataset : series)
        if (uidOf(dataset, "0020000E") == seriesUid) count = integerOf(dataset, "00201209");
    const std::string url = base_ + "/studies/" + studyUid + "/series/" + seriesUid + "/instances?" +
                            (count && *count >= 1 ? "limit=1&" : "") +
                            "includefield=00280010&includefield=00280011&includefield=00280008";
    json instances = parseDatasets(config_, scrubber_, http.get(url, kJson, config_.maxQueryBytes), url);
    if (instances.empty())
        throw DicomWebError(ErrorKind::NotFound, sourceText(config_) + " has no instances of series " + seriesUid +
                                                     " in study " + studyUid);
    if (count && *count >= 1) instances = json::array({instances.at(0)});
    SeriesSize size;
    for (const json &dataset : instances) {
        ++size.instances;
        const auto rows = integerOf(dataset, "00280010");
        const auto columns = integerOf(dataset, "00280011");
        const int64_t frames = integerOf(dataset, "00280008").value_or(1);
        const auto usable = [](const std::optional<int64_t> &v) { return v && *v >= 1 && *v <= 65535; };
        if (!usable(rows) || !usable(columns) || frames < 1 || frames > (int64_t(1) << 24))
            throw DicomWebError(ErrorKind::BadResponse,
                                sourceText(config_) + " gave instance " + std::to_string(size.instances) + " of series " +
                                    seriesUid + " no usable Rows, Columns or NumberOfFrames");
        size.rows = std::max(size.rows, *rows);
        size.columns = std::max(size.columns, *columns);
        const uint64_t bytes = uint64_t(frames) * uint64_t(*rows) * uint64_t(*columns) * sizeof(float);
        size.float32Bytes = bytes > std::numeric_limits<uint64_t>::max() - size.float32Bytes
                                ? std::numeric_limits<uint64_t>::max()
                                : size.float32Bytes + bytes;
    }
    if (count && *count >= 1) {
        // Every instance taken to be as large as the first; the product saturates, never wraps.
        const uint64_t n = uint64_t(*count);
        size.instances = *count;
        size.float32Bytes = size.float32Bytes > std::numeric_limits<uint64_t>::max() / n
                                ? std::numeric_limits<uint64_t>::max()
                                : size.float32Bytes * n;
    }
    return size;
}

RetrieveProgress Client::retrieve(const std::string &studyUid, const std::string &seriesUid,
                                  const std::filesystem::path &folder, uint64_t maxBytes,
                                  const std::function<void(const RetrieveProgress &)> &progress,
                                  const std::function<bool()> &cancelled, int64_t expectedInstances) {
    checkUids(config_, studyUid, seriesUid);
    const std::string src = sourceText(config_);
    const std::string url = base_ + "/studies/" + studyUid + "/series/" + seriesUid;
    std::error_code ec;
    const bool folderExisted = std::filesystem::exists(folder, ec);
    std::filesystem::create_directories(folder, ec);
    if (ec) throw DicomWebError(ErrorKind::Storage, folder.string() + " could not be created: " + ec.message());
    // Files left from another retrieval would be loaded as part of this series.
    if (folderExisted && !std::filesystem::is_empty(folder, ec))
        throw DicomWebError(ErrorKind::Storage, folder.string() + " is not empty: a series is retrieved into an empty folder");

    RetrieveProgress state;
    state.instancesTotal = std::max<int64_t>(0, expectedInstances);
    std::vector<std::filesystem::path> written;
    std::optional<InstanceFile> file;
    std::optional<MultipartReader> reader;
    // "instance 3": the one being received (1-based), for messages.
    const auto instanceText = [&]() -> std::string {
        const size_t begun = reader ? reader->partsBegun() : 0;
        const size_t ended = reader ? reader->partsEnded() : 0;
        if (begun > ended) return "instance " + std::to_string(begun);
        return ended == 0 ? std::string("before the first instance") : "after instance " + std::to_string(ended);
    };
    const auto seriesText = "series " + seriesUid;

    MultipartReader::Callbacks callbacks;
    callbacks.partBegin = [&](const MultipartHeaders &headers) {
        const size_t number = reader->partsBegun();
        const std::string type = headers.get("Content-Type");
        if (type.empty())
            throw DicomWebError(ErrorKind::BadResponse, src + " sent instance " + std::to_string(number) + " of " +
                                                            seriesText + " without a Content-Type");
        std::string media;
        try {
            media = parseContentType(type).mediaType;
        } catch (const MultipartError &) {
        }
        if (media != "application/dicom")
            throw DicomWebError(ErrorKind::BadResponse, src + " sent instance " + std::to_string(number) + " of " +
                                                            seriesText + " as '" + cleanText(scrubber_.withoutCredentials(type)) +
                                                            "', not application/dicom");
        char name[32];
        std::snprintf(name, sizeof name, "instance_%05zu.dcm", number - 1);
        written.push_back(folder / name);
        file.emplace(written.back());
    };
    callbacks.partData = [&](std::string_view data) {
        state.bytes += data.size();
        if (state.bytes > maxBytes)
            throw DicomWebError(ErrorKind::TooLarge, src + ": " + seriesText + " is larger than the " +
                                                         std::to_string(maxBytes) + " bytes allowed (at " +
                                                         instanceText() + ")");
        file->write(data);
    };
    callbacks.partEnd = [&] {
        file->close();
        file.reset();
        ++state.instancesDone;
        if (progress) progress(state);
    };
    MultipartLimits limits;
    limits.maxParts = 100000;  // instance_NNNNN
    limits.maxPartBytes = std::numeric_limits<uint64_t>::max();  // maxBytes bounds the whole series, below

    const auto onHead = [&](const ResponseHead &head) {
        ContentType type;
        std::string boundary;
        try {
            type = parseContentType(head.contentType);
            if (type.mediaType != "multipart/related") throw MultipartError("not multipart/related");
            const std::string partType = type.parameter("type");
            if (!partType.empty() && parseContentType(partType).mediaType != "application/dicom")
                throw MultipartError("its parts are not application/dicom");
            boundary = multipartBoundary(head.contentType);
        } catch (const MultipartError &e) {
            throw DicomWebError(ErrorKind::BadResponse, src + " answered GET " + HttpClient::pathForMessage(url) +
                                                            " with Content-Type '" + cleanText(scrubber_.withoutCredentials(head.contentType)) +
                                                            "': " + e.what());
        }
        reader.emplace(boundary, callbacks, limits);
    };
    const auto onData = [&](std::string_view chunk) {
        try {
            reader->feed(chunk);
        } catch (const MultipartError &e) {
            throw DicomWebError(ErrorKind::BadResponse,
                                src + " sent a malformed multipart body for " + seriesText + " at " + instanceText() + ": " + e.what());
        }
    };

    try {
        HttpClient http(httpOptions(config_, true));
        http.getStreaming(url, kMultipartDicom, onHead, onData, cancelled);
        if (!reader)  // a 2xx without a body never gave its head to onHead
            throw DicomWebError(ErrorKind::BadResponse, src + " answered GET " + HttpClient::pathForMessage(url) + " with no body");
        try {
            reader->finish();
        } catch (const MultipartError &e) {
            throw DicomWebError(ErrorKind::BadResponse, src + " ended " + seriesText + " early, at " + instanceText() +
                                                            " (truncated): " + e.what());
        }
        if (state.instancesDone == 0)
            throw DicomWebError(ErrorKind::NotFound, src + " sent no instance of " + seriesText);
        if (expectedInstances > 0 && state.instancesDone != expectedInstances)
            throw DicomWebError(ErrorKind::BadResponse, src + " sent " + std::to_string(state.instancesDone) + " instances of " +
                                                            seriesText + ", its metadata listed " +
                                                            std::to_string(expectedInstances));
    } catch (const DicomWebError &e) {
        file.reset();
        for (const auto &path : written) std::filesystem::remove(path, ec);
        if (!folderExisted) std::filesystem::remove(folder, ec);  // only if empty
        // Errors of the transfer itself (connection lost, timeout) say where in the series.
        const std::string message = e.what();
        if (message.find("instance") == std::string::npos && reader)
            throw DicomWebError(e.kind, message + " (" + seriesText + ", " + instanceText() + ")");
        throw;
    }
    spdlog::debug("{}: {} instances, {} bytes retrieved", src, state.instancesDone, state.bytes);
    return state;
}

} // namespace volcast::dicomweb
