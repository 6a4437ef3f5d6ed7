// volcast-dicom-check: the child process in which volcast parses DICOM before loading it
// itself (volume_io.hpp, runDicomCheck). Installed next to volcast-server.

#include "renderer/io/dicom_check.hpp"

int main(int argc, char **argv) { return volcast::runDicomCheck(argc, argv); }
