// A small CT series as DICOM Part 10 files, written here with no library: explicit VR little
// endian, one signed 16-bit slice per file, axial, with the patient, study and series
// attributes a PACS indexes. Enough for Orthanc to store and serve it over DICOMweb and for
// volcast's loader (ITK/GDCM) to read it back as a volume.

import { randomBytes } from "node:crypto";

// A fresh UID under the UUID-derived root 2.25 (PS3.5 B.2): digits only, at most 44 characters.
export const newUid = () => `2.25.${BigInt(`0x${randomBytes(16).toString("hex")}`)}`;

const LONG_LENGTH_VRS = new Set(["OB", "OW", "OF", "SQ", "UT", "UN"]);

function element(group, elementNo, vr, value) {
  let data;
  if (vr === "US") { data = Buffer.alloc(2); data.writeUInt16LE(value); }
  else if (vr === "UL") { data = Buffer.alloc(4); data.writeUInt32LE(value); }
  else if (Buffer.isBuffer(value)) data = value;
  else data = Buffer.from(String(value), "latin1");
  if (data.length % 2) data = Buffer.concat([data, Buffer.from(vr === "UI" || vr === "OB" ? [0] : [0x20])]);
  const long = LONG_LENGTH_VRS.has(vr);
  const head = Buffer.alloc(long ? 12 : 8);
  head.writeUInt16LE(group, 0);
  head.writeUInt16LE(elementNo, 2);
  head.write(vr, 4, "latin1");
  if (long) head.writeUInt32LE(data.length, 8); else head.writeUInt16LE(data.length, 6);
  return Buffer.concat([head, data]);
}

const CT_IMAGE_STORAGE = "1.2.840.10008.5.1.4.1.1.2";
const EXPLICIT_VR_LITTLE_ENDIAN = "1.2.840.10008.1.2.1";

// One file: the 128-byte preamble, "DICM", the file meta group, then the data set.
function dicomFile(sopInstanceUid, elements) {
  const meta = Buffer.concat([
    element(0x0002, 0x0001, "OB", Buffer.from([0, 1])),
    element(0x0002, 0x0002, "UI", CT_IMAGE_STORAGE),
    element(0x0002, 0x0003, "UI", sopInstanceUid),
    element(0x0002, 0x0010, "UI", EXPLICIT_VR_LITTLE_ENDIAN),
    element(0x0002, 0x0012, "UI", "2.25.1"),
  ]);
  return Buffer.concat([Buffer.alloc(128), Buffer.from("DICM"), element(0x0002, 0x0000, "UL", meta.length), meta, ...elements]);
}

// The series: `slices` files of columns × rows int16 voxels, voxel(x, y, z) giving each value
// (Hounsfield units). Returns {studyUid, seriesUid, files: [Buffer]}.
export function ctSeries({
  patientName = "DOE^JANE", patientId = "VOLCAST-0001", studyDate = "20240131", studyDescription = "Synthetic head",
  seriesDescription = "Axial ball", accessionNumber = "ACC0001", columns = 16, rows = 16, slices = 8,
  spacing = [1, 1, 2], voxel = (x, y, z) => (Math.hypot(x - (columns - 1) / 2, y - (rows - 1) / 2, (z - (slices - 1) / 2) * spacing[2] / spacing[0]) < columns / 3 ? 1000 : -1000),
} = {}) {
  const studyUid = newUid(), seriesUid = newUid(), frameUid = newUid();
  const files = [];
  for (let z = 0; z < slices; z++) {
    const sop = newUid();
    const pixels = Buffer.alloc(columns * rows * 2);
    for (let y = 0; y < rows; y++) for (let x = 0; x < columns; x++) pixels.writeInt16LE(voxel(x, y, z), (y * columns + x) * 2);
    files.push(dicomFile(sop, [
      element(0x0008, 0x0008, "CS", "ORIGINAL\\PRIMARY\\AXIAL"),
      element(0x0008, 0x0016, "UI", CT_IMAGE_STORAGE),
      element(0x0008, 0x0018, "UI", sop),
      element(0x0008, 0x0020, "DA", studyDate),
      element(0x0008, 0x0030, "TM", "101500"),
      element(0x0008, 0x0050, "SH", accessionNumber),
      element(0x0008, 0x0060, "CS", "CT"),
      element(0x0008, 0x1030, "LO", studyDescription),
      element(0x0008, 0x103e, "LO", seriesDescription),
      element(0x0010, 0x0010, "PN", patientName),
      element(0x0010, 0x0020, "LO", patientId),
      element(0x0018, 0x0050, "DS", String(spacing[2])),
      element(0x0020, 0x000d, "UI", studyUid),
      element(0x0020, 0x000e, "UI", seriesUid),
      element(0x0020, 0x0010, "SH", "1"),
      element(0x0020, 0x0011, "IS", "1"),
      element(0x0020, 0x0013, "IS", String(z + 1)),
      element(0x0020, 0x0032, "DS", `0\\0\\${z * spacing[2]}`),
      element(0x0020, 0x0037, "DS", "1\\0\\0\\0\\1\\0"),
      element(0x0020, 0x0052, "UI", frameUid),
      element(0x0028, 0x0002, "US", 1),
      element(0x0028, 0x0004, "CS", "MONOCHROME2"),
      element(0x0028, 0x0010, "US", rows),
      element(0x0028, 0x0011, "US", columns),
      element(0x0028, 0x0030, "DS", `${spacing[1]}\\${spacing[0]}`),
      element(0x0028, 0x0100, "US", 16),
      element(0x0028, 0x0101, "US", 16),
      element(0x0028, 0x0102, "US", 15),
      element(0x0028, 0x0103, "US", 1),
      element(0x0028, 0x1052, "DS", "0"),
      element(0x0028, 0x1053, "DS", "1"),
      element(0x7fe0, 0x0010, "OW", pixels),
    ]));
  }
  return { studyUid, seriesUid, files };
}
