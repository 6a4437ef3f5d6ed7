"""Client.upload and Client.open_array against a real volcast-server (VOLCAST_SERVER_EXE,
started on a free port by tests/soak/serverproc.py): a NRRD file uploaded over
POST /api/volumes opens by the name the server answered, a numpy volume sent with
open_array comes back with its own dims, spacing, origin, direction and values, and the
server's refusals reach the script as UploadError with their HTTP status. The offline
tests (../python/test_upload.py, test_nrrd.py) check the bytes the client sends; these check
that the server reads them as meant.

Run: VOLCAST_SERVER_EXE=build/server/volcast-server PYTHONPATH=client/python \\
     /usr/bin/python3 -m unittest discover -s tests/protocol/python_live -v"""

import asyncio
import math
import os
import sys
import tempfile
import unittest

import numpy as np

import volcast as vc

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "soak"))
import serverproc  # noqa: E402

TOKEN = "python-live-upload-token"
# The server reports geometry as doubles read from the NRRD's text, which the client writes
# with repr (exact); 1e-9 leaves room for the direction's normalisation (a division by a
# length that is 1 within rounding).
GEOMETRY_TOLERANCE = 1e-9


def setUpModule():
    global server
    exe = os.environ.get("VOLCAST_SERVER_EXE")
    if not exe:
        raise RuntimeError("VOLCAST_SERVER_EXE must name the built volcast-server")
    # With a token: uploads then need it, and the client sends the one it connected with.
    server = serverproc.Server(exe, ["--log-level", "info", "--token", TOKEN], ready_timeout=60)


def tearDownModule():
    code, _ = server.stop()
    server.cleanup()
    if code != 0:
        raise RuntimeError(f"volcast-server exited with {code} on SIGTERM")


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 120))


def rotation_z(degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


class LiveUploadTests(unittest.TestCase):
    def connect(self, token=TOKEN):
        return vc.Client.connect(f"ws://127.0.0.1:{server.port}/ws", token=token, client_name="python_live_upload")

    def assert_close(self, got, want, what):
        flat_got, flat_want = np.ravel(np.asarray(got, float)), np.ravel(np.asarray(want, float))
        self.assertEqual(flat_got.shape, flat_want.shape, f"{what}: {got} vs {want}")
        self.assertLess(np.abs(flat_got - flat_want).max(), GEOMETRY_TOLERANCE, f"{what}: got {got}, want {want}")

    def test_an_uploaded_nrrd_file_opens_by_its_name(self):
        # Written by hand, not by the client's NRRD writer: 5 x 4 x 3 uint8 samples 0..59,
        # spacing 0.5 x 1 x 2, origin (10, -20, 30).
        data = bytes(range(60))
        header = ("NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\nsizes: 5 4 3\n"
                  "space directions: (0.5,0,0) (0,1,0) (0,0,2)\nkinds: domain domain domain\n"
                  "encoding: raw\nspace origin: (10,-20,30)\n\n").encode()
        with tempfile.TemporaryDirectory(prefix="volcast-live-upload-") as tmp:
            path = os.path.join(tmp, "ramp.nrrd")
            with open(path, "wb") as f:
                f.write(header + data)

            async def body():
                async with await self.connect() as client:
                    progress = []
                    name = await client.upload(path, on_progress=lambda sent, total: progress.append((sent, total)))
                    state = await client.open_volume(name, timeout=60)
                    return name, progress, state

            name, progress, state = run(body())
        self.assertRegex(name, r"^upload:[0-9a-f]{32}$")
        self.assertEqual(progress[-1], (len(header) + 60, len(header) + 60))
        volume = state["volume"]
        self.assertEqual(volume["name"], name)
        self.assertEqual(volume["dims"], [5, 4, 3])
        self.assert_close(volume["spacing"], [0.5, 1, 2], "spacing")
        self.assert_close(volume["origin"], [10, -20, 30], "origin")
        self.assertEqual(volume["voxel_type"], "uint8")
        self.assertEqual(volume["value_range"], [0, 59])
        self.assertTrue(volume["orientation_known"], "the NRRD's space field was not seen")

    def test_open_array_gives_the_arrays_geometry_and_values(self):
        # 12 x 10 x 6 (x, y, z): numpy shape (6, 10, 12); oblique (30 degrees about z),
        # anisotropic, away from the origin, and negative values (int16, as CT).
        nz, ny, nx = 6, 10, 12
        k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
        array = (i * 100 + j * 10 + k - 700).astype(np.int16)
        spacing, origin, direction = (0.7, 0.8, 2.5), (-120.5, 33.25, 7.0), rotation_z(30)

        async def body():
            async with await self.connect() as client:
                return await client.open_array(array, spacing=spacing, origin=origin, direction=direction,
                                               name="ramp", timeout=60)

        state = run(body())
        volume = state["volume"]
        self.assertRegex(volume["name"], r"^upload:[0-9a-f]{32}$")
        # dims are x, y, z: the array's shape reversed.
        self.assertEqual(volume["dims"], [nx, ny, nz])
        self.assert_close(volume["spacing"], spacing, "spacing")
        self.assert_close(volume["origin"], origin, "origin")
        self.assert_close(volume["direction"], direction, "direction")
        self.assertEqual(volume["voxel_type"], "int16")
        self.assertEqual(volume["value_range"], [int(array.min()), int(array.max())])
        self.assertEqual(sum(volume["histogram"]["counts"]), array.size)

    def test_open_array_voxels_land_where_numpy_indexes_them(self):
        # One bright voxel at array[z=1, y=2, x=5] of an otherwise empty volume: an axial
        # slice through its world position shows it, and one through another z does not.
        array = np.zeros((4, 6, 8), np.uint8)
        array[1, 2, 5] = 255
        spacing = (1.0, 1.0, 1.0)

        async def body():
            async with await self.connect() as client:
                await client.open_array(array, spacing=spacing, timeout=60)
                at = await client.request_slice("axial", 8, 6, point=[5, 2, 1], center=[3.5, 2.5, 1],
                                                pixel_spacing=1, window=255, level=127.5, timeout=60)
                off = await client.request_slice("axial", 8, 6, point=[5, 2, 2], center=[3.5, 2.5, 2],
                                                 pixel_spacing=1, window=255, level=127.5, timeout=60)
                return at, off

        at, off = run(body())
        pixels = at.to_numpy()
        row, column = np.unravel_index(np.argmax(pixels), pixels.shape)
        # Axial columns run along +x and rows along +y: pixel (column, row) shows world (x, y).
        x, y, _ = at.world_at(column, row)
        self.assertEqual((round(x), round(y)), (5, 2), f"the bright voxel shows at world x={x}, y={y}")
        self.assertEqual(pixels.max(), 255)
        self.assertEqual(off.to_numpy().max(), 0, "the bright voxel shows in the slice above it too")

    def test_refusals_reach_the_script_with_their_status(self):
        with tempfile.TemporaryDirectory(prefix="volcast-live-upload-") as tmp:
            garbage = os.path.join(tmp, "garbage.nrrd")
            with open(garbage, "wb") as f:
                f.write(b"this is not a volume\n" * 10)
            unknown = os.path.join(tmp, "notes.txt")
            with open(unknown, "wb") as f:
                f.write(b"x")

            async def status_of(path, token=TOKEN):
                async with await self.connect() as client:
                    client.token = token   # a session opened with the token, an upload without it
                    with self.assertRaises(vc.UploadError) as caught:
                        await client.upload(path)
                    return caught.exception

            for path, token, status in ((garbage, TOKEN, 422), (unknown, TOKEN, 415), (garbage, None, 401)):
                with self.subTest(file=os.path.basename(path), token=bool(token)):
                    error = run(status_of(path, token))
                    self.assertEqual(error.status, status, str(error))
                    self.assertTrue(error.message and "\n" not in error.message, repr(error.message))
                    # The server's message names no server path (its upload folder).
                    self.assertNotIn(tempfile.gettempdir() + os.sep, error.message)


if __name__ == "__main__":
    unittest.main()
