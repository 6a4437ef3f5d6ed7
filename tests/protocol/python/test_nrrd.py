"""The in-memory NRRD that Client.open_array uploads: its bytes parse back (header fields,
sizes in x y z order for a numpy array indexed [z, y, x], the geometry, the voxels, little
endian), every dtype the server loads maps to its NRRD type, and unsupported arrays are
refused with a ValueError that says what to do.

The NRRD is parsed here by a few lines written from the format's specification
(teem.sourceforge.net/nrrd/format.html), not by the writer's own code; the live tests
(../python_live) open the same bytes in the real server. Needs numpy (Debian: python3-numpy);
skips, saying so, without it."""

import struct
import unittest

import volcast as vc

try:
    import numpy as np
except ImportError:
    np = None

NEEDS = "numpy is not installed (Debian: python3-numpy, in deploy/install.sh)"


def parse_nrrd(data):
    """(fields, voxel bytes) of an attached-data NRRD: the magic line, `key: value` lines,
    `#` comments, a blank line, then the data."""
    head, sep, voxels = data.partition(b"\n\n")
    assert sep, "no blank line ends the header"
    lines = head.decode("ascii").split("\n")
    assert lines[0] == "NRRD0004", f"magic line {lines[0]!r}"
    fields = {}
    for line in lines[1:]:
        if line.startswith("#"):
            continue
        key, colon, value = line.partition(": ")
        assert colon, f"not a field line: {line!r}"
        assert key not in fields, f"field {key!r} twice"
        fields[key] = value
    return fields, voxels


def vectors(text):
    """'(1,0,0) (0,1,0)' -> [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"""
    return [[float(x) for x in part.strip("()").split(",")] for part in text.split()]


@unittest.skipIf(np is None, NEEDS)
class NrrdBytes(unittest.TestCase):
    def test_a_small_int16_volume_parses_back(self):
        # 2 slices (z) of 3 rows (y) of 4 columns (x): the file's sizes are x y z = 4 3 2.
        array = np.arange(24, dtype=np.int16).reshape(2, 3, 4) * 100 - 1000
        fields, voxels = parse_nrrd(vc.nrrd_bytes(array))
        self.assertEqual(fields, {
            "type": "int16", "dimension": "3", "space": "left-posterior-superior", "sizes": "4 3 2",
            "space directions": "(1.0,0.0,0.0) (0.0,1.0,0.0) (0.0,0.0,1.0)",
            "kinds": "domain domain domain", "endian": "little", "encoding": "raw",
            "space origin": "(0.0,0.0,0.0)"})
        self.assertEqual(len(voxels), 24 * 2)
        # NRRD's first axis (x) varies fastest: sample (x=i, y=j, z=k) is at (k*3 + j)*4 + i.
        for k, j, i in ((0, 0, 0), (0, 0, 3), (0, 2, 1), (1, 0, 0), (1, 2, 3)):
            offset = ((k * 3 + j) * 4 + i) * 2
            self.assertEqual(struct.unpack_from("<h", voxels, offset)[0], array[k, j, i],
                             f"voxel array[{k}, {j}, {i}] is not at x={i} y={j} z={k}")

    def test_geometry_is_written_in_patient_space(self):
        # direction's columns are the x, y, z axes: here x runs along -P, y along +L, z along +S.
        direction = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
        fields, _ = parse_nrrd(vc.nrrd_bytes(np.zeros((5, 6, 7), np.uint8), spacing=(0.5, 0.75, 2.5),
                                             origin=(-10, 20.25, 1e-3), direction=direction))
        steps = vectors(fields["space directions"])
        self.assertEqual(steps, [[0, -0.5, 0], [0.75, 0, 0], [0, 0, 2.5]])
        self.assertEqual(vectors(fields["space origin"]), [[-10, 20.25, 1e-3]])
        self.assertEqual(fields["sizes"], "7 6 5")

    def test_every_supported_dtype_maps_to_its_nrrd_type(self):
        expected = {"int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16",
                    "int32": "int32", "uint32": "uint32", "float32": "float", "float64": "double"}
        self.assertEqual(vc.NRRD_TYPES, expected)
        for name, nrrd_type in expected.items():
            with self.subTest(dtype=name):
                array = (np.arange(8).reshape(2, 2, 2) + 1).astype(name)
                fields, voxels = parse_nrrd(vc.nrrd_bytes(array))
                self.assertEqual(fields["type"], nrrd_type)
                self.assertEqual(voxels, array.astype(np.dtype(name).newbyteorder("<")).tobytes())
                # Byte order means nothing for one-byte samples; NRRD leaves the field out.
                self.assertEqual("endian" in fields, np.dtype(name).itemsize > 1)

    def test_big_endian_and_non_contiguous_arrays_are_written_in_order(self):
        big = np.arange(24, dtype=">u2").reshape(2, 3, 4)
        _, voxels = parse_nrrd(vc.nrrd_bytes(big))
        self.assertEqual(np.frombuffer(voxels, "<u2").tolist(), list(range(24)))
        # A transposed view: its [z, y, x] order is what is written, not its memory order.
        base = np.arange(60, dtype=np.float32).reshape(3, 4, 5)
        view = base.transpose(2, 1, 0)[:, ::2]   # shape (5, 2, 3), not contiguous
        fields, voxels = parse_nrrd(vc.nrrd_bytes(view))
        self.assertEqual(fields["sizes"], "3 2 5")
        np.testing.assert_array_equal(np.frombuffer(voxels, "<f4").reshape(5, 2, 3), view)

    def test_a_contiguous_little_endian_array_is_sent_without_a_copy(self):
        array = np.ones((4, 4, 4), np.float32)
        header, voxels = vc.encode_nrrd(array)
        self.assertTrue(np.shares_memory(np.frombuffer(voxels, np.uint8), array),
                        "encode_nrrd copied an array that was already C-contiguous little-endian")
        self.assertEqual(voxels.nbytes, array.nbytes)
        self.assertTrue(header.endswith(b"\n\n"))

    def test_unsupported_dtypes_are_refused_saying_what_to_do(self):
        cases = [
            (np.zeros((2, 2, 2), bool), "boolean arrays are not supported.*uint8"),
            (np.zeros((2, 2, 2), np.complex64), r"complex arrays \(complex64\).*numpy.abs"),
            (np.empty((2, 2, 2), object), "arrays of object are not supported"),
            (np.zeros((2, 2, 2), np.int64), "arrays of int64 are not supported.*astype"),
            (np.zeros((2, 2, 2), np.float16), "arrays of float16 are not supported"),
            (np.zeros((2, 2, 2), "U3"), "arrays of <U3 are not supported"),
        ]
        for array, message in cases:
            with self.subTest(dtype=str(array.dtype)):
                with self.assertRaisesRegex(ValueError, "open_array: " + message):
                    vc.encode_nrrd(array)

    def test_arrays_that_are_not_3d_are_refused(self):
        for shape in ((4, 4), (2, 2, 2, 3), (5,), ()):
            with self.subTest(shape=shape):
                with self.assertRaisesRegex(ValueError, rf"must be 3-D, indexed \[z, y, x\]; got {len(shape)}-D"):
                    vc.encode_nrrd(np.zeros(shape, np.uint8))
        with self.assertRaisesRegex(ValueError, "at least one sample"):
            vc.encode_nrrd(np.zeros((3, 0, 3), np.uint8))

    def test_bad_geometry_is_refused(self):
        a = np.zeros((2, 2, 2), np.uint8)
        for kwargs, message in [
            ({"spacing": (1, 1)}, "spacing must be 3 numbers"),
            ({"spacing": (1, 0, 1)}, "spacing must be positive"),
            ({"spacing": (1, float("nan"), 1)}, "spacing must be finite"),
            ({"origin": (0, 0, float("inf"))}, "origin must be finite"),
            ({"origin": "abc"}, "origin must be 3 numbers"),
            ({"direction": [[1, 0, 0], [0, 1, 0]]}, "direction must be 3 rows"),
            ({"direction": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}, r"direction column 0 \(the x axis\) must have unit length"),
            ({"direction": [[1, 0, 0], [0, 0.5, 0], [0, 0, 1]]}, r"column 1 \(the y axis\) must have unit length"),
        ]:
            with self.subTest(**{k: str(v) for k, v in kwargs.items()}):
                with self.assertRaisesRegex(ValueError, message):
                    vc.encode_nrrd(a, **kwargs)
        # Unit columns, but y and z point the same way.
        s = 0.5 ** 0.5
        with self.assertRaisesRegex(ValueError, "direction is singular"):
            vc.encode_nrrd(a, direction=[[1, s, s], [0, s, s], [0, 0, 0]])


if __name__ == "__main__":
    unittest.main()
