"""Offline tests of the measurement requests (probe, roi_stats, pick), the slab and the
projection window in the volcast package, and of the Client's measurement calls against a
stand-in socket.

Run: PYTHONPATH=client/python /usr/bin/python3 -m unittest discover -s tests/protocol/python"""

import asyncio
import json
import math
import unittest

import volcast as vc
from test_client import FakeSocket, jpeg_frame


class MeasurementRequestTests(unittest.TestCase):
    def test_builders_write_the_wire_form(self):
        self.assertEqual(vc.probe((1, 2.5, -3), id=4), {"type": "probe", "id": 4, "point": [1.0, 2.5, -3.0]})
        self.assertEqual(vc.roi_stats("coronal", [0, 1, 2], (3, 4), id="r"),
                         {"type": "roi_stats", "id": "r", "axis": "coronal", "center": [0.0, 1.0, 2.0],
                          "radii": [3.0, 4.0], "shape": "ellipse"})
        self.assertEqual(vc.roi_stats("axial", [0, 0, 0], [1, 1], shape="rectangle")["shape"], "rectangle")
        self.assertEqual(vc.pick(10.5, 20.5, 640, 480, id=2),
                         {"type": "pick", "id": 2, "x": 10.5, "y": 20.5, "width": 640, "height": 480})
        self.assertEqual(vc.slice_request("axial", 8, 8, slab=vc.slab(5, "mean"))["slab"],
                         {"thickness": 5.0, "mode": "mean"})
        self.assertEqual(vc.with_compositing(compositing="mip", window=vc.projection_window(400, 40)),
                         {"compositing": "mip", "projection_window": {"window": 400.0, "level": 40.0}})

    def test_builders_refuse_what_the_server_would(self):
        for bad in ([1, 2], [1, 2, math.nan], [1, math.inf, 3]):
            with self.assertRaises(ValueError):
                vc.probe(bad)
        for radii in ([1], [1, 0], [-1, 2], [1, math.inf]):
            with self.assertRaises(ValueError):
                vc.roi_stats("axial", [0, 0, 0], radii)
        with self.assertRaises(ValueError):
            vc.roi_stats("oblique", [0, 0, 0], [1, 1])
        with self.assertRaises(ValueError):
            vc.roi_stats("axial", [0, 0, 0], [1, 1], shape="star")
        for thickness, mode in ((-1, "mip"), (math.nan, "mip"), (2, "max")):
            with self.assertRaises(ValueError):
                vc.slab(thickness, mode)
        for window, level in ((0, 1), (-1, 1), (math.inf, 1), (1, math.nan)):
            with self.assertRaises(ValueError):
                vc.projection_window(window, level)

    def test_slab_is_read_from_the_slice_header(self):
        header = {"request": 3, "axis": "axial", "width": 1, "height": 1, "format": "gray8", "pixel_spacing": 1,
                  "origin": [0, 0, 0], "column": [1, 0, 0], "row": [0, 1, 0], "point": [0, 0, 0],
                  "window": 1, "level": 0, "render_ms": 1, "slab": {"thickness": 4, "mode": "mip", "planes": 9}}
        self.assertEqual(vc.decode_slice(vc.encode_slice(header, b"\x00")).slab["planes"], 9)
        del header["slab"]
        self.assertIsNone(vc.decode_slice(vc.encode_slice(header, b"\x00")).slab)


class ClientMeasurementTests(unittest.TestCase):
    def test_each_call_returns_its_answer_and_keeps_the_rest(self):
        async def scenario():
            probe = {"type": "probe", "id": 1, "point": [1, 2, 3], "inside": True, "value": -998.5, "unit": "HU"}
            roi = {"type": "roi_stats", "id": 2, "samples": 0, "area_mm2": 0, "mean": None, "std": None,
                   "min": None, "max": None, "unit": None}
            pick = {"type": "pick", "id": 3, "hit": False, "point": None, "opacity": 0.1}
            socket = FakeSocket([jpeg_frame(1, None), json.dumps(probe), json.dumps(roi), json.dumps(pick)])
            client = vc.Client(socket)
            self.assertEqual(await client.probe([1, 2, 3]), probe)
            self.assertEqual(await client.roi_stats("axial", [1, 2, 3], [4, 5]), roi)
            self.assertEqual(await client.pick(1.5, 2.5, 10, 10), pick)
            self.assertEqual([m["type"] for m in socket.sent], ["probe", "roi_stats", "pick"])
            self.assertIsInstance(await client.receive(timeout=0), vc.Frame)
        asyncio.run(asyncio.wait_for(scenario(), 5))

    def test_an_error_answering_it_is_raised(self):
        async def scenario():
            error = {"type": "error", "id": 1, "code": "bad_state", "message": "open a volume first",
                     "request_type": "probe"}
            client = vc.Client(FakeSocket([json.dumps(error)]))
            with self.assertRaisesRegex(vc.ServerError, "bad_state"):
                await client.probe([0, 0, 0])
        asyncio.run(asyncio.wait_for(scenario(), 5))


if __name__ == "__main__":
    unittest.main()
