#include "protocol/volume_name.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>
#include <utility>
#include <vector>

namespace volcast::protocol {
namespace {

using namespace std::string_literals;

TEST(VolumeName, AcceptsRelativeNamesInsideTheDataFolders) {
    for (const std::string name : {"bonsai", "ct/head.nrrd", "bonsai.nhdr", "a/b/c/d.nii.gz", ".hidden",
                                   "builtin:phantom", "name with spaces", "kopf_ä.nrrd", "x..y"}) {
        EXPECT_EQ(validateVolumeName(name), std::nullopt) << name;
    }
}

TEST(VolumeName, RefusesEachKindWithItsOwnMessage) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"", "is empty"},
        {std::string(1025, 'a'), "is 1025 bytes long; at most 1024 are allowed"},
        {"bon\0sai"s, "contains a NUL character (at byte 3)"},
        {"bon\x1bsai", "contains a control character (0x1B at byte 3)"},
        {"bon\x7fsai", "contains a control character (0x7F at byte 3)"},
        {"ct\\head.nrrd", "contains a backslash; separate folders with \"/\""},
        {"/etc/passwd", "is an absolute path; give a name relative to the server's data folders"},
        {"C:/data/x", "starts with a drive letter; give a name relative to the server's data folders"},
        {"~/scans/x", "starts with \"~\"; home folders are not reachable"},
        {"ct//head", "has an empty path component (\"//\" or a trailing \"/\")"},
        {"series-01/", "has an empty path component (\"//\" or a trailing \"/\")"},
        {"..", "contains a \"..\" component; names must stay inside the data folders"},
        {"../etc/passwd", "contains a \"..\" component; names must stay inside the data folders"},
        {"ct/../../x", "contains a \"..\" component; names must stay inside the data folders"},
        {"ct/..", "contains a \"..\" component; names must stay inside the data folders"},
        {"./bonsai", "contains a \".\" component"},
        {std::string(256, 'a'), "has a component of 256 bytes; at most 255 are allowed"},
    };
    std::set<std::string> kinds;
    for (const auto &[name, message] : cases) {
        const auto problem = validateVolumeName(name);
        ASSERT_TRUE(problem.has_value()) << name;
        EXPECT_EQ(*problem, message);
        kinds.insert(*problem);
    }
    // Distinct messages for distinct problems: 17 cases, of which two are empty components
    // and four are ".." components, one message each.
    EXPECT_EQ(kinds.size(), 13u);
}

TEST(VolumeName, AStackOfASeriesIsNamedByTheSeriesNameAndItsNumber) {
    for (const std::string name : {"dicomweb:pacs/1.2.3/1.2.3.4#stack=1", "ct/series#stack=2", "upload:abc#stack=99999"})
        EXPECT_EQ(validateVolumeName(name), std::nullopt) << name;
    const StackSelection selection = splitStackSelection("dicomweb:pacs/1.2.3/1.2.3.4#stack=12");
    EXPECT_EQ(selection.series, "dicomweb:pacs/1.2.3/1.2.3.4");
    EXPECT_EQ(selection.stack, 12u);
    EXPECT_EQ(stackVolumeName("ct/series", 3), "ct/series#stack=3");
    EXPECT_EQ(splitStackSelection("ct/series").stack, std::nullopt);
    EXPECT_EQ(splitStackSelection("ct/series").series, "ct/series");
    const std::string noNumber = "has a \"#stack=\" that is not followed by a stack number (1 to 99999) at its end";
    for (const std::string name : {"ct/series#stack=", "ct/series#stack=0", "ct/series#stack=01", "ct/series#stack=-1",
                                   "ct/series#stack=100000", "ct/series#stack=1x", "#stack=1", "ct/series#stack=1/x"})
        EXPECT_EQ(validateVolumeName(name), noNumber) << name;
    EXPECT_EQ(validateVolumeName("ct/series#stack=1#stack=2"), "names a stack twice (\"#stack=\")");
}

TEST(VolumeName, LengthLimitIsAParameter) {
    EXPECT_EQ(validateVolumeName("abcdef", 6), std::nullopt);
    EXPECT_EQ(validateVolumeName("abcdefg", 6), "is 7 bytes long; at most 6 are allowed");
}

} // namespace
} // namespace volcast::protocol
