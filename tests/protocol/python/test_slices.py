"""Offline tests of the slice request and message in the volcast package (slices.py) and of
Client.slice against a stand-in socket.

Run: PYTHONPATH=client/python /usr/bin/python3 -m unittest discover -s tests/protocol/python"""

import asyncio
import json
import unittest

import volcast as vc
from test_client import FakeSocket, jpeg_frame

HEADER = {"request": 3, "axis": "sagittal", "width": 3, "height": 2, "format": "gray8",
          "pixel_spacing": 0.5, "origin": [1, 2, 3], "column": [0, 1, 0], "row": [0, 0, -1],
          "point": [4, 5, 6], "window": 2000, "level": 400, "render_ms": 1.5}
PIXELS = bytes([0, 10, 20, 30, 40, 255])


class SliceMessageTests(unittest.TestCase):
    def test_round_trip_and_geometry(self):
        data = vc.encode_slice(HEADER, PIXELS)
        self.assertTrue(vc.is_slice_message(data))
        s = vc.decode_slice(data)
        self.assertEqual(s.request, 3)
        self.assertEqual((s.width, s.height), (3, 2))
        self.assertEqual(s.pixels, PIXELS)
        # Pixel (2, 1): origin + 2·0.5·column + 1·0.5·row.
        self.assertEqual(s.world_at(2, 1), (1, 3, 2.5))
        # A frame decoder refuses it: a slice is never mistaken for a 3D frame.
        with self.assertRaisesRegex(vc.FrameError, "VCF1"):
            vc.decode_frame(data)

    def test_damaged_messages_are_refused_naming_the_problem(self):
        data = vc.encode_slice(HEADER, PIXELS)
        with self.assertRaisesRegex(vc.FrameError, "5 pixel bytes"):
            vc.decode_slice(data[:-1])
        with self.assertRaisesRegex(vc.FrameError, "VCS1"):
            vc.decode_slice(b"VCF1" + data[4:])
        with self.assertRaisesRegex(vc.FrameError, "format"):
            vc.decode_slice(vc.encode_slice(dict(HEADER, format="rgba8"), PIXELS))
        with self.assertRaisesRegex(vc.FrameError, r"origin\[1\]"):
            vc.decode_slice(vc.encode_slice(dict(HEADER, origin=[0, "x", 0]), PIXELS))

    def test_framing_is_checked_as_for_frames(self):
        # Slices and frames share their framing (frames._decode_binary): every cut of a slice
        # message is refused, and each refusal of the preamble and header starts with "slice".
        data = vc.encode_slice(HEADER, PIXELS)
        for n in range(len(data)):
            with self.assertRaises(vc.FrameError, msg=f"{n} bytes"):
                vc.decode_slice(data[:n])
        with self.assertRaisesRegex(vc.FrameError, "^slice: 6 bytes, shorter than the 8-byte preamble"):
            vc.decode_slice(data[:6])
        with self.assertRaisesRegex(vc.FrameError, r"^slice: header length \d+ runs past the message's end .*truncated\?"):
            vc.decode_slice(data[:50])
        with self.assertRaisesRegex(vc.FrameError, "^slice: header length .* over the limit of 65536"):
            vc.decode_slice(data[:7] + b"\x7f" + data[8:])
        with self.assertRaisesRegex(vc.FrameError, "^slice header: malformed JSON"):
            vc.decode_slice(data[:8] + b"[" + data[9:])
        text = b"[1, 2]"
        with self.assertRaisesRegex(vc.FrameError, "^slice header: must be a JSON object, got list"):
            vc.decode_slice(b"VCS1" + len(text).to_bytes(4, "little") + text)
        # The encoder refuses a header the decoder would refuse.
        with self.assertRaisesRegex(vc.FrameError, "^slice header: .* over the limit of 65536"):
            vc.encode_slice(dict(HEADER, axis="x" * 70000), PIXELS)

    def test_request_builder_keeps_only_given_fields(self):
        self.assertEqual(vc.slice_request("axial", 64, 32, id=1),
                         {"type": "slice", "id": 1, "axis": "axial", "width": 64, "height": 32})
        self.assertEqual(vc.slice_request("coronal", 8, 8, point=(1, 2, 3), window=400, level=40)["point"], [1, 2, 3])
        with self.assertRaises(ValueError):
            vc.slice_request("oblique", 8, 8)

    def test_to_numpy_is_height_by_width(self):
        try:
            import numpy  # noqa: F401
        except ImportError:
            self.skipTest("numpy is not installed (python3-numpy)")
        array = vc.decode_slice(vc.encode_slice(HEADER, PIXELS)).to_numpy()
        self.assertEqual(array.shape, (2, 3))
        self.assertEqual(array.dtype.name, "uint8")
        self.assertEqual(array[1, 2], 255)


class ClientSliceTests(unittest.TestCase):
    def test_slice_waits_for_its_answer_and_keeps_the_rest(self):
        async def scenario():
            socket = FakeSocket([jpeg_frame(1, None), vc.encode_slice(dict(HEADER, request=1), PIXELS)])
            client = vc.Client(socket)
            s = await client.request_slice("sagittal", 3, 2, point=[4, 5, 6])
            self.assertEqual(socket.sent, [{"type": "slice", "id": 1, "axis": "sagittal", "width": 3,
                                            "height": 2, "point": [4, 5, 6]}])
            self.assertEqual(s.pixels, PIXELS)
            self.assertIsInstance(await client.receive(timeout=0), vc.Frame)
        asyncio.run(asyncio.wait_for(scenario(), 5))

    def test_slice_raises_the_error_answering_it(self):
        async def scenario():
            error = {"type": "error", "id": 1, "code": "bad_state", "message": "open a volume",
                     "request_type": "slice"}
            client = vc.Client(FakeSocket([json.dumps(error)]))
            with self.assertRaisesRegex(vc.ServerError, "bad_state"):
                await client.slice("axial", 4, 4)
        asyncio.run(asyncio.wait_for(scenario(), 5))


if __name__ == "__main__":
    unittest.main()
