// What the client refuses before anything is sent: bad filters, UIDs, base URLs and
// credentials; and how accepted filters are encoded into the QIDO-RS query.

#include "dicomweb/dicomweb_client.hpp"

#include <gtest/gtest.h>

#include <string>

using namespace volcast::dicomweb;

namespace {

// The BadQuery message for `query`, or "" when it is accepted.
std::string refusal(const StudyQuery &query) {
    try {
        studyQueryString(query);
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::BadQuery) << e.what();
        return e.what();
    }
    return {};
}

SourceConfig source(std::string name, std::string baseUrl, std::string authorization = {}) {
    SourceConfig c;
    c.name = std::move(name);
    c.baseUrl = std::move(baseUrl);
    c.authorization = std::move(authorization);
    return c;
}

} // namespace

TEST(DicomWebQuery, FiltersAreSentPercentEncodedInTheirOrder) {
    StudyQuery q;
    q.patientName = "DOE^J*";
    q.patientId = "ID 7/8";
    q.studyDate = "20240101-";
    q.modality = "CT";
    q.accessionNumber = "A&B=C";
    q.limit = 5;
    // '^', '*', '?' and '/' as they are (Orthanc 1.10 matches only those), '&', '=', '+',
    // '%', spaces and non-ASCII bytes escaped.
    EXPECT_EQ(studyQueryString(q), "PatientName=DOE^J*&PatientID=ID%207/8&StudyDate=20240101-&ModalitiesInStudy=CT"
                                   "&AccessionNumber=A%26B%3DC&limit=5&includefield=00081030&includefield=00080061");
    EXPECT_EQ(studyQueryString(StudyQuery{}), "limit=100&includefield=00081030&includefield=00080061")
        << "empty filters are not sent";
    StudyQuery utf8;
    utf8.patientName = "M\xc3\xbcller?+%";
    EXPECT_EQ(studyQueryString(utf8).substr(0, 31), "PatientName=M%C3%BCller?%2B%25&");
}

TEST(DicomWebQuery, ControlCharactersBackslashesAndBadUtf8AreRefusedNamingTheField) {
    StudyQuery q;
    q.patientName = "DOE\r\nX-Injected: 1";
    EXPECT_NE(refusal(q).find("patient_name holds a control character"), std::string::npos);
    q = {};
    q.patientId = std::string("A\0B", 3);
    EXPECT_NE(refusal(q).find("patient_id holds a control character"), std::string::npos);
    q = {};
    q.accessionNumber = "A\\B";
    EXPECT_NE(refusal(q).find("accession_number holds a backslash"), std::string::npos);
    q = {};
    q.patientName = "\xc3(";
    EXPECT_NE(refusal(q).find("patient_name is not valid UTF-8"), std::string::npos);
    q = {};
    q.modality = "C-T";
    EXPECT_NE(refusal(q).find("modality may hold only"), std::string::npos);
}

TEST(DicomWebQuery, ValuesLongerThanDicomAllowsAreRefused) {
    StudyQuery q;
    q.patientName = std::string(64, 'A');
    EXPECT_EQ(refusal(q), "");
    q.patientName += "A";
    EXPECT_NE(refusal(q).find("patient_name is longer than 64 bytes"), std::string::npos);
    q = {};
    q.accessionNumber = std::string(17, '1');  // SH: 16 characters
    EXPECT_NE(refusal(q).find("accession_number is longer than 16"), std::string::npos);
}

TEST(DicomWebQuery, DatesAreYyyymmddOrRanges) {
    for (const char *good : {"20240229", "20240101-20241231", "-20240101", "20240101-", "20240101-20240101"}) {
        StudyQuery q;
        q.studyDate = good;
        EXPECT_EQ(refusal(q), "") << good;
    }
    for (const char *bad : {"2024-01-01", "20241301", "20240100", "2024010", "-", "20240101-2024", "2024O101",
                            "20240101-20240102-20240103", "20241231-20240101"}) {
        StudyQuery q;
        q.studyDate = bad;
        EXPECT_NE(refusal(q).find("study_date"), std::string::npos) << bad;
    }
}

TEST(DicomWebQuery, LimitMustBeOneToAThousand) {
    StudyQuery q;
    q.limit = 0;
    EXPECT_NE(refusal(q).find("limit must be 1 to 1000, not 0"), std::string::npos);
    q.limit = 1001;
    EXPECT_NE(refusal(q).find("not 1001"), std::string::npos);
    q.limit = 1000;
    EXPECT_EQ(refusal(q), "");
}

TEST(DicomWebQuery, UidsAreDigitsAndSingleDotsUpTo64) {
    EXPECT_TRUE(isUid("1.2.840.10008.1.2.1"));
    EXPECT_TRUE(isUid("7"));
    EXPECT_TRUE(isUid(std::string(64, '1')));
    EXPECT_FALSE(isUid(std::string(65, '1')));
    EXPECT_FALSE(isUid(""));
    EXPECT_FALSE(isUid(".1.2"));
    EXPECT_FALSE(isUid("1.2."));
    EXPECT_FALSE(isUid("1..2"));
    EXPECT_FALSE(isUid("1.2/../3"));
    EXPECT_FALSE(isUid("1.2?x=1"));
    EXPECT_FALSE(isUid("1.2 3"));
}

TEST(DicomWebQuery, BadUidsAreRefusedBeforeAnyRequest) {
    // Port 9 (discard) on loopback: were a request made, it would fail as Unreachable.
    Client client(source("pacs", "http://127.0.0.1:9/dicom-web"));
    try {
        client.seriesSize("1.2.3", "1.2/../../x");
        FAIL() << "a bad series UID was accepted";
    } catch (const DicomWebError &e) {
        EXPECT_EQ(e.kind, ErrorKind::BadQuery);
        EXPECT_NE(std::string(e.what()).find("series UID is not a DICOM UID"), std::string::npos) << e.what();
    }
    EXPECT_THROW(client.retrieveSeries("1..2", "1.2", "/nonexistent", 1, {}, {}), DicomWebError);
}

TEST(DicomWebQuery, BaseUrlsAndAuthorizationValuesAreChecked) {
    const auto refused = [](SourceConfig config) -> std::string {
        try {
            Client client(std::move(config));
        } catch (const DicomWebError &e) {
            EXPECT_EQ(e.kind, ErrorKind::BadQuery);
            return e.what();
        }
        return {};
    };
    EXPECT_EQ(refused(source("a", "https://pacs.example.org/dicom-web/")), "");
    EXPECT_NE(refused(source("a", "ftp://pacs/dicom-web")).find("http:// or https://"), std::string::npos);
    EXPECT_NE(refused(source("a", "http:///dicom-web")).find("no host"), std::string::npos);
    const std::string withCredentials = refused(source("a", "http://user:secret@pacs/dicom-web"));
    EXPECT_NE(withCredentials.find("holds credentials"), std::string::npos);
    EXPECT_EQ(withCredentials.find("secret"), std::string::npos) << "the message must not repeat them";
    EXPECT_NE(refused(source("a", "http://pacs/dicom-web?x=1")).find("no query"), std::string::npos);
    const std::string auth = refused(source("a", "http://pacs/", "Basic abc\r\nX-Evil: 1"));
    EXPECT_NE(auth.find("line break"), std::string::npos);
    EXPECT_EQ(auth.find("abc"), std::string::npos) << "the message must not repeat the Authorization value";
}
