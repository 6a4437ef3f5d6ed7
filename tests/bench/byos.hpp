#pragma once
// volcast-bench byos: bringing your own scan, timed against what it is compared with
// (tests/bench/README.md, docs/data-sources.md "Figures").

#include <filesystem>

namespace volcast::bench {

struct ByosOptions {
    std::filesystem::path out = "out/bench";
    int rounds = 3;       // each round times every measurement once, in turn (interleaved)
    bool quick = false;   // tiny volumes, one round: checks the command works, times nothing
};

// A DICOM series served by a real Orthanc (started here) against volcast's first frame of it
// over DICOMweb, and a .nii.gz's parse time against its upload's first frame. Prints a table
// and writes byos.json and byos.md into options.out. Throws std::runtime_error naming what
// failed (Orthanc missing, a refused upload, an error from the server).
void byosStudy(const ByosOptions &options);

} // namespace volcast::bench
