"""Offline tests of the volcast package (client/python/volcast): frames, message building,
the README's example session, and the Client's request/frame logic against a stand-in socket.

Run: PYTHONPATH=client/python /usr/bin/python3 -m unittest discover -s tests/protocol/python
(ctest runs it as protocol.python_client)."""

import asyncio
import json
import os
import re
import struct
import unittest

import volcast as vc

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("VOLCAST_PROTOCOL_TEST_DATA", os.path.join(HERE, "..", "data"))
README = os.environ.get("VOLCAST_PROTOCOL_README",
                        os.path.join(HERE, "..", "..", "..", "protocol", "README.md"))

# The header tests/protocol/data/frame_example.hex holds (the C++ tests use the same file).
EXAMPLE_HEADER = {
    "seq": 42, "request": 17, "level": 2, "quality": {"step": 0.25, "interpolation": "cubic"},
    "width": 4, "height": 2, "codec": "png", "render_ms": 12.5, "encode_ms": 1.25,
    "error": {"value": 0.0042, "method": "rmse_vs_next_level"}, "final": True,
    "camera": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0],
               "projection": "perspective", "fov_y_deg": 30},
}
EXAMPLE_IMAGE = b"\x89PNG\r\n\x1a\n"


def read_hex(path):
    digits = "".join(line.split("#")[0].strip() for line in open(path))
    return bytes.fromhex(digits)


def frame_with(header, image=b""):
    text = json.dumps(header).encode()
    return b"VCF1" + struct.pack("<I", len(text)) + text + image


class FrameTests(unittest.TestCase):
    def test_documented_bytes_decode(self):
        golden = read_hex(os.path.join(DATA, "frame_example.hex"))
        frame = vc.decode_frame(golden)
        self.assertEqual(frame.header, dict(EXAMPLE_HEADER, image_bytes=8))
        self.assertEqual(frame.image, EXAMPLE_IMAGE)
        self.assertEqual((frame.seq, frame.request, frame.level, frame.codec, frame.final),
                         (42, 17, 2, "png", True))
        self.assertEqual(frame.error, {"value": 0.0042, "method": "rmse_vs_next_level"})

    def test_encoder_writes_the_documented_bytes(self):
        # Same bytes as the C++ encoder: the two implementations agree on the layout.
        golden = read_hex(os.path.join(DATA, "frame_example.hex"))
        self.assertEqual(vc.encode_frame(EXAMPLE_HEADER, EXAMPLE_IMAGE), golden)

    def test_round_trip(self):
        for image in (b"", b"\x00\x01", bytes(70000)):
            frame = vc.decode_frame(vc.encode_frame(EXAMPLE_HEADER, image))
            self.assertEqual(frame.image, image)
            self.assertEqual(frame.header["image_bytes"], len(image))

    def test_every_truncation_is_refused(self):
        message = vc.encode_frame(EXAMPLE_HEADER, bytes(100))
        for n in range(len(message)):
            with self.assertRaises(vc.FrameError, msg=f"{n} bytes"):
                vc.decode_frame(message[:n])
        with self.assertRaisesRegex(vc.FrameError, "shorter than the 8-byte preamble"):
            vc.decode_frame(message[:6])
        with self.assertRaisesRegex(vc.FrameError, r"runs past the message's end .*truncated\?"):
            vc.decode_frame(message[:50])
        with self.assertRaisesRegex(vc.FrameError, r"image_bytes is 100 but 99 bytes .*truncated\?"):
            vc.decode_frame(message[:-1])

    def test_garbled_frames_are_refused(self):
        good = vc.encode_frame(EXAMPLE_HEADER, EXAMPLE_IMAGE)
        with self.assertRaisesRegex(vc.FrameError, "not the magic"):
            vc.decode_frame(b"VCF2" + good[4:])
        with self.assertRaisesRegex(vc.FrameError, "over the limit of 65536"):
            vc.decode_frame(good[:7] + b"\x7f" + good[8:])
        with self.assertRaisesRegex(vc.FrameError, "image_bytes is 8 but 9 bytes"):
            vc.decode_frame(good + b"\x00")
        with self.assertRaisesRegex(vc.FrameError, "malformed JSON"):
            vc.decode_frame(good[:8] + b"[" + good[9:])
        with self.assertRaisesRegex(vc.FrameError, "must be a JSON object"):
            vc.decode_frame(frame_with([1, 2]))

    def test_header_fields_are_checked(self):
        good = {"seq": 1, "level": 0, "width": 2, "height": 2, "codec": "jpeg", "render_ms": 3.5,
                "encode_ms": 1, "final": False, "image_bytes": 0}
        vc.decode_frame(frame_with(good))
        vc.decode_frame(frame_with(dict(good, gpu_temperature=60)))  # unknown fields ignored
        for key in ("seq", "width", "codec", "final", "image_bytes"):
            broken = {k: v for k, v in good.items() if k != key}
            with self.assertRaisesRegex(vc.FrameError, f"{key}: is required"):
                vc.decode_frame(frame_with(broken))
        with self.assertRaisesRegex(vc.FrameError, "unknown codec 'webp'"):
            vc.decode_frame(frame_with(dict(good, codec="webp")))
        with self.assertRaisesRegex(vc.FrameError, "final: must be true or false"):
            vc.decode_frame(frame_with(dict(good, final=1)))
        with self.assertRaisesRegex(vc.FrameError, "width: must be an integer"):
            vc.decode_frame(frame_with(dict(good, width=True)))
        with self.assertRaisesRegex(vc.FrameError, "width: must be at least 1, got 0"):
            vc.decode_frame(frame_with(dict(good, width=0)))
        with self.assertRaisesRegex(vc.FrameError, "seq: must be at least 0, got -1"):
            vc.decode_frame(frame_with(dict(good, seq=-1)))
        # A pass of refinement at rest says its number; other frames have none (0).
        self.assertEqual(vc.decode_frame(frame_with(dict(good, rest_pass=2))).rest_pass, 2)
        self.assertEqual(vc.decode_frame(frame_with(good)).rest_pass, 0)
        for bad in (-1, 65, 1.5, True):
            with self.assertRaisesRegex(vc.FrameError, "rest_pass: must be an integer"):
                vc.decode_frame(frame_with(dict(good, rest_pass=bad)))


class MessageTests(unittest.TestCase):
    def test_builders(self):
        cam = EXAMPLE_HEADER["camera"]
        cases = [
            (vc.hello(client="t", id=1), {"type": "hello", "id": 1, "protocol": 1, "client": "t"}),
            (vc.hello(token="s"), {"type": "hello", "protocol": 1, "token": "s"}),
            (vc.list_volumes(), {"type": "list_volumes"}),
            (vc.open_volume("ct/head.nrrd", id="o"), {"type": "open_volume", "id": "o", "name": "ct/head.nrrd"}),
            (vc.camera(cam, id=3), {"type": "camera", "id": 3, "camera": cam}),
            (vc.interaction_start(), {"type": "interaction_start"}),
            (vc.interaction_end(), {"type": "interaction_end"}),
            (vc.viewport(640, 480), {"type": "viewport", "image": {"width": 640, "height": 480}}),
            (vc.transfer_function({"preset": "ct_bone"}),
             {"type": "transfer_function", "transfer_function": {"preset": "ct_bone"}}),
            (vc.quality_automatic(), {"type": "quality_policy", "mode": "automatic", "target_frame_ms": 40}),
            (vc.quality_automatic(25, {"shading": True}),
             {"type": "quality_policy", "mode": "automatic", "target_frame_ms": 25, "quality": {"shading": True}}),
            (vc.quality_explicit({"step": 0.25}),
             {"type": "quality_policy", "mode": "explicit", "quality": {"step": 0.25}}),
            (vc.clip_planes([]), {"type": "clip_planes", "clip_planes": []}),
            (vc.still(), {"type": "still"}),
            (vc.still(2048, 1024), {"type": "still", "image": {"width": 2048, "height": 1024}}),
            (vc.get_state(), {"type": "get_state"}),
            (vc.close(), {"type": "close"}),
            (vc.slice_request("axial", 64, 32), {"type": "slice", "axis": "axial", "width": 64, "height": 32}),
            (vc.find_studies("pacs"), {"type": "find_studies", "source": "pacs", "filters": {}, "limit": 100}),
            (vc.probe([1, 2, 3]), {"type": "probe", "point": [1.0, 2.0, 3.0]}),
            (vc.roi_stats("axial", [1, 2, 3], [4, 5]),
             {"type": "roi_stats", "axis": "axial", "center": [1.0, 2.0, 3.0], "radii": [4.0, 5.0], "shape": "ellipse"}),
            (vc.pick(1.5, 2.5, 8, 8), {"type": "pick", "x": 1.5, "y": 2.5, "width": 8, "height": 8}),
        ]
        for built, expected in cases:
            self.assertEqual(built, expected)
            self.assertIn(built["type"], vc.CLIENT_TYPES)
            self.assertEqual(json.loads(vc.dumps(built)), built)
        self.assertEqual({m["type"] for m, _ in cases}, set(vc.CLIENT_TYPES))
        with self.assertRaises(ValueError):
            vc.still(width=10)
        with self.assertRaises(TypeError):
            vc.open_volume(5)

    def test_compositing_and_crop_box_in_the_quality(self):
        q = vc.with_compositing({"step": 0.5}, "mip", vc.crop_box([0, 0.2, 0], [1, 0.8, 0.5]))
        self.assertEqual(q, {"step": 0.5, "compositing": "mip",
                             "crop": {"min": [0.0, 0.2, 0.0], "max": [1.0, 0.8, 0.5]}})
        self.assertEqual(vc.quality_explicit(q)["quality"]["compositing"], "mip")
        self.assertEqual(vc.with_compositing(None, "minip"), {"compositing": "minip"})
        with self.assertRaisesRegex(ValueError, "compositing must be one of"):
            vc.with_compositing({}, "max")
        with self.assertRaisesRegex(ValueError, "axis 1 needs 0 <= min < max <= 1"):
            vc.crop_box([0, 0.5, 0], [1, 0.5, 1])
        with self.assertRaisesRegex(ValueError, "3 numbers"):
            vc.crop_box([0, 0], [1, 1, 1])

    def test_dumps_is_compact_and_refuses_nan(self):
        self.assertEqual(vc.dumps(vc.open_volume("b", id=1)), '{"type":"open_volume","id":1,"name":"b"}')
        with self.assertRaises(ValueError):
            vc.dumps(vc.quality_automatic(float("nan")))

    def test_parse_server_message(self):
        m = vc.parse_server_message('{"type": "error", "id": 3, "code": "not_found", "message": "x"}')
        self.assertEqual(m["code"], "not_found")
        for bad in ("{", "[]", '{"id": 1}', '{"type": 5}'):
            with self.assertRaises(vc.MessageError, msg=bad):
                vc.parse_server_message(bad)

    def test_orbit_camera_keeps_distance_and_turns_about_up(self):
        base = {"eye": [10, 2, 0], "target": [0, 2, 0], "up": [0, 1, 0], "projection": "perspective",
                "fov_y_deg": 30}
        quarter = vc.orbit_camera(base, 90)
        for got, want in zip(quarter["eye"], [0, 2, -10]):
            self.assertAlmostEqual(got, want, places=9)  # rotation about +y takes +x to -z
        self.assertEqual(quarter["fov_y_deg"], 30)
        for got, want in zip(vc.orbit_camera(base, 360)["eye"], base["eye"]):
            self.assertAlmostEqual(got, want, places=9)


def read_readme():
    with open(README, encoding="utf-8") as f:
        return f.read()


def documented_types(text):
    """The message types the README gives a `### \`type\`` section, client's and server's."""
    sections = {"## Client → server": "C", "## Server → client": "S"}
    side, found = None, {"C": set(), "S": set()}
    for line in text.splitlines():
        if line.startswith("## "):
            side = sections.get(line.strip())
        elif side and line.startswith("### "):
            found[side].update(re.findall(r"`([a-z_]+)`", line))
    return found


class ReadmeExampleTests(unittest.TestCase):
    def test_the_client_knows_every_documented_message(self):
        documented = documented_types(read_readme())
        self.assertGreater(len(documented["C"]), 10, "no client message sections found in the README")
        self.assertLessEqual(documented["C"], set(vc.CLIENT_TYPES), "client messages the package cannot build")
        self.assertLessEqual(documented["S"], set(vc.SERVER_TYPES), "server messages the package does not name")

    def test_every_line_decodes(self):
        lines, inside = [], False
        for line in read_readme().splitlines():
            line = line.rstrip("\n")
            if line == "<!-- example-session:begin -->":
                inside = True
            elif line == "<!-- example-session:end -->":
                inside = False
            elif inside and line[:3] in ("C: ", "S: "):
                lines.append(line)
        self.assertGreater(len(lines), 30)
        seen = set()
        for i, line in enumerate(lines):
            with self.subTest(line=line[:80]):
                text = line[3:]
                if line.startswith("C: "):
                    message = json.loads(text)
                    if message["type"] in vc.CLIENT_TYPES:
                        seen.add(("C", message["type"]))
                    else:  # shown on purpose: the server's answer follows
                        answer = vc.parse_server_message(lines[i + 1][3:])
                        self.assertEqual((answer["code"], answer["id"]), ("unknown_type", message["id"]))
                elif text.startswith("frame "):
                    header = json.loads(text[6:])
                    frame = vc.decode_frame(frame_with(header, bytes(header["image_bytes"])))
                    self.assertEqual(frame.codec, "png" if frame.final else "jpeg")
                    seen.add(("S", "frame"))
                else:
                    message = vc.parse_server_message(text)
                    self.assertIn(message["type"], vc.SERVER_TYPES)
                    self.assertIn("id", message)
                    if message["type"] == "error":
                        self.assertIn(message["code"], vc.ERROR_CODES)
                    seen.add(("S", message["type"]))
        # Every message the README documents is in its example session. (The package may know
        # a message before the README documents it: those are not required here.)
        documented = documented_types(read_readme())
        why = "messages the README documents (and the package knows) but its example session does not show"
        self.assertEqual({t for side, t in seen if side == "C"}, set(vc.CLIENT_TYPES) & documented["C"], why)
        self.assertEqual({t for side, t in seen if side == "S"},
                         (set(vc.SERVER_TYPES) & documented["S"]) | {"frame"}, why)


class FakeSocket:
    """Stands in for a websockets connection: replies are queued by the test."""

    def __init__(self, incoming):
        self.incoming = asyncio.Queue()
        for item in incoming:
            self.incoming.put_nowait(item)
        self.sent = []
        self.closed = False

    async def send(self, text):
        self.sent.append(json.loads(text))

    async def recv(self):
        return await self.incoming.get()

    async def close(self):
        self.closed = True


def jpeg_frame(seq, request, final=False):
    header = dict(EXAMPLE_HEADER, seq=seq, request=request, final=final, codec="png" if final else "jpeg")
    return vc.encode_frame(header, b"img%d" % seq)


class ClientTests(unittest.TestCase):
    def run_async(self, coroutine):
        return asyncio.run(asyncio.wait_for(coroutine, 5))

    def test_request_skips_progress_and_keeps_other_messages(self):
        async def scenario():
            socket = FakeSocket([
                jpeg_frame(1, None),
                json.dumps({"type": "progress", "id": 1, "volume": "b", "stage": "loading", "fraction": 0.5}),
                json.dumps({"type": "state", "id": 1, "volume": None, "scene": {},
                            "quality_policy": {"mode": "automatic"}, "interacting": False}),
            ])
            client = vc.Client(socket)
            progress = []
            state = await client.request(vc.open_volume("b"), on_progress=progress.append)
            self.assertEqual(state["type"], "state")
            self.assertEqual(socket.sent, [{"type": "open_volume", "id": 1, "name": "b"}])
            self.assertEqual([p["fraction"] for p in progress], [0.5])
            # The frame read while waiting is still there for receive().
            kept = await client.receive(timeout=0)
            self.assertIsInstance(kept, vc.Frame)
            self.assertEqual(kept.seq, 1)
            self.assertIsNone(await client.receive(timeout=0.01))
        self.run_async(scenario())

    def test_request_raises_the_error_answering_it(self):
        async def scenario():
            error = {"type": "error", "id": "x", "code": "bad_volume_name", "message": "nope",
                     "request_type": "open_volume"}
            client = vc.Client(FakeSocket([json.dumps(error)]))
            with self.assertRaises(vc.ServerError) as caught:
                await client.request(vc.open_volume("../x", id="x"))
            self.assertEqual(caught.exception.code, "bad_volume_name")
            self.assertEqual(caught.exception.id, "x")
        self.run_async(scenario())

    def test_a_series_of_several_stacks_raises_with_the_stacks_to_open(self):
        async def scenario():
            stacks = [{"volume": "ct/series#stack=1", "slices": 120, "rows": 512, "columns": 512,
                       "orientation": "axial", "localizer": False},
                      {"volume": "ct/series#stack=2", "slices": 1, "rows": 256, "columns": 256,
                       "orientation": "coronal", "localizer": True}]
            error = {"type": "error", "id": "x", "code": "load_failed", "request_type": "open_volume",
                     "message": "ct/series: the series holds a localizer besides 120 axial slices", "stacks": stacks}
            client = vc.Client(FakeSocket([json.dumps(error)]))
            with self.assertRaises(vc.ServerError) as caught:
                await client.request(vc.open_volume("ct/series", id="x"))
            self.assertEqual(caught.exception.stacks, stacks)
            self.assertEqual(vc.ServerError({"code": "not_found", "message": "m"}).stacks, [],
                             "an error without stacks has none")
        self.run_async(scenario())

    def test_wait_for_final_frame_of_a_request(self):
        async def scenario():
            client = vc.Client(FakeSocket([jpeg_frame(1, 7), jpeg_frame(2, 7, final=True),
                                           jpeg_frame(3, 9), jpeg_frame(4, 9, final=True)]))
            earlier = []
            final = await client.wait_for_final_frame(request=9, on_frame=earlier.append)
            self.assertEqual(final.seq, 4)
            self.assertEqual(final.image, b"img4")
            # Every frame before the one waited for is handed over, 7's final frame included.
            self.assertEqual([f.seq for f in earlier], [1, 2, 3])
        self.run_async(scenario())

    def test_wait_for_final_frame_raises_on_its_error_and_times_out(self):
        async def scenario():
            error = {"type": "error", "id": 5, "code": "render_failed", "message": "out of memory"}
            client = vc.Client(FakeSocket([jpeg_frame(1, 5), json.dumps(error)]))
            with self.assertRaisesRegex(vc.ServerError, "render_failed"):
                await client.wait_for_final_frame(request=5)
            with self.assertRaises(asyncio.TimeoutError):
                await client.wait_for_final_frame(timeout=0.01)
        self.run_async(scenario())

    def test_ids_are_assigned_and_close_says_close(self):
        async def scenario():
            socket = FakeSocket([])
            async with vc.Client(socket) as client:
                self.assertEqual(await client.send(vc.get_state()), 1)
                self.assertEqual(await client.send(vc.get_state(id="mine")), "mine")
                self.assertEqual(await client.send(vc.get_state()), 2)
            self.assertEqual(socket.sent[-1], {"type": "close"})
            self.assertTrue(socket.closed)
        self.run_async(scenario())


if __name__ == "__main__":
    unittest.main()
