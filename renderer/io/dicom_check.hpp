#pragma once

// DICOM is parsed first in a child process, the DICOM checker (`volcast-dicom-check`), which
// runs the same load as loadVolume; only if it survives is the file loaded in the caller. A
// GDCM assertion, a crash or a runaway parse on a hostile file then ends the child, not the
// server, and the load fails with a VolumeLoadError saying so. This applies to folders (DICOM
// series) and to files that no other reader (NRRD, MetaImage, NIfTI) claims. The checker is
// found through $VOLCAST_DICOM_CHECK, next to the running executable (installed), or in the
// build tree; where none is found such a load fails: it is never parsed in-process unchecked.

namespace volcast {

// The checker's main: loads argv[1] in this process with the limits argv gives and reports
// by its exit status (dicom_child.cpp). Not for other callers.
int runDicomCheck(int argc, char **argv);

} // namespace volcast
