"""The Python client against a real volcast-server (VOLCAST_SERVER_EXE, started on a free port
by tests/soak/serverproc.py): what a script does with MIP, the crop box and slices, end to
end. The offline tests beside it (../python) check the messages; these check that the server
does what they ask.

Run: VOLCAST_SERVER_EXE=build/server/volcast-server PYTHONPATH=client/python \
     /usr/bin/python3 -m unittest discover -s tests/protocol/python_live -v"""

import asyncio
import os
import sys
import unittest

import numpy as np

import volcast as vc

# The soak tests' server process: free port, /readyz, its log's tail when it fails to start.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "soak"))
import serverproc  # noqa: E402

SIZE = 96   # px: small frames keep the test quick on the CPU back end
EXPLICIT = {"step": 0.5, "jitter": False, "early_termination": 1.0}
GREY_RAMP = [[0, 0, 0, 0, 0], [255, 1, 1, 1, 1]]   # colour and opacity follow the value


def setUpModule():
    global server
    exe = os.environ.get("VOLCAST_SERVER_EXE")
    if not exe:
        raise RuntimeError("VOLCAST_SERVER_EXE must name the built volcast-server")
    server = serverproc.Server(exe, ["--log-level", "info"], ready_timeout=60)


def tearDownModule():
    code, _ = server.stop()
    server.cleanup()
    if code != 0:
        raise RuntimeError(f"volcast-server exited with {code} on SIGTERM")


async def open_demo(client):
    state = await client.request(vc.open_volume("builtin:demo"), timeout=60)
    await client.send(vc.viewport(SIZE, SIZE))
    return state


def axis_camera(state, side, axis=2):
    """Orthographic, looking at the volume's centre along world axis `axis` (towards −axis for
    side +1, +axis for side −1), +y up (+z when looking along y), the whole volume in view."""
    v = state["volume"]
    centre = [v["origin"][i] + (v["dims"][i] - 1) * v["spacing"][i] / 2 for i in range(3)]
    size = max(v["dims"][i] * v["spacing"][i] for i in range(3))
    eye = list(centre)
    eye[axis] += side * 3 * size
    up = [0, 0, 1] if axis == 1 else [0, 1, 0]
    return {"eye": eye, "target": centre, "up": up, "projection": "orthographic", "height": 1.25 * size}


async def final_rgba(client, quality, camera=None):
    """The final frame of an explicit policy (and camera, when given) as float RGBA in [0, 1]."""
    last = await client.send(vc.quality_explicit(quality))
    if camera is not None:
        last = await client.send(vc.camera(camera))
    frame = await client.wait_for_final_frame(request=last, timeout=60)
    return frame, frame.to_numpy().astype(np.float64) / 255


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 120))


class LiveServerTests(unittest.TestCase):
    def connect(self):
        return vc.Client.connect(f"ws://127.0.0.1:{server.port}/ws", client_name="python_live")

    def test_mip_does_not_depend_on_the_ray_direction(self):
        # A maximum is the same whichever way a ray runs: an orthographic view from the
        # opposite side is the mirror image. The phantom's vessel tree is not symmetric, so
        # the two views differ unless mirrored.
        async def body():
            async with await self.connect() as client:
                state = await open_demo(client)
                await client.send(vc.transfer_function({"points": GREY_RAMP}))
                q = vc.with_compositing(EXPLICIT, "mip")
                f, front = await final_rgba(client, q, axis_camera(state, +1, axis=0))
                self.assertEqual(f.quality["compositing"], "mip")
                _, back = await final_rgba(client, q, axis_camera(state, -1, axis=0))
                return front, back

        front, back = run(body())
        self.assertGreater(front[..., 3].mean(), 0.05, "the MIP image is empty")
        mirrored_off = np.abs(front - back[:, ::-1]).mean()
        plain_off = np.abs(front - back).mean()
        # 0.002: half an 8-bit level on average, where the two directions' samples could fall
        # at different depths (step 0.5 voxel; here they fall at mirrored ones, and it is 0).
        self.assertLess(mirrored_off, 0.002, f"MIP front vs mirrored back: mean |diff| {mirrored_off:.5f}")
        self.assertGreater(plain_off, 1e-3, f"the two views are alike unmirrored ({plain_off:.5f}): nothing was checked")

    def test_crop_box_keeps_only_the_half_it_names(self):
        # Seen along −z with +y up, +x is the image's right: a box cut to the lower half along
        # x leaves the image's left half only, split at the centre column (orthographic).
        async def body():
            async with await self.connect() as client:
                state = await open_demo(client)
                _, whole = await final_rgba(client, EXPLICIT, axis_camera(state, +1))
                f, kept = await final_rgba(client, vc.with_compositing(EXPLICIT, crop=vc.crop_box([0, 0, 0], [0.5, 1, 1])))
                self.assertEqual(f.quality["crop"], {"min": [0, 0, 0], "max": [0.5, 1, 1]})
                return whole, kept

        whole, kept = run(body())
        alpha, middle = kept[..., 3], SIZE // 2
        self.assertGreater(whole[:, middle:, 3].mean(), 0.02, "nothing to crop on the image's right")
        # One column's margin: the cut lies on the boundary between the two middle columns.
        self.assertEqual(alpha[:, middle + 1:].max(), 0, "the cropped-away half (image right) is not empty")
        # The kept half is untouched away from the cut (exact partial segments at the face).
        self.assertLess(np.abs(kept[:, :middle - 1] - whole[:, :middle - 1]).max(), 2 / 255,
                        "the half kept changed")

    def test_slices_come_back_with_their_geometry(self):
        async def body():
            async with await self.connect() as client:
                state = await open_demo(client)
                axial = await client.request_slice("axial", 64, 48, timeout=60)
                coronal = await client.request_slice("coronal", 64, 48, timeout=60)
                return state, axial, coronal

        state, axial, coronal = run(body())
        for s in (axial, coronal):
            self.assertEqual((s.width, s.height), (64, 48))
            self.assertGreater((s.to_numpy() > 12).mean(), 0.05, f"{s.header['axis']}: a blank slice")
        # Axial planes are perpendicular to z: columns along +x, rows along +y (anterior on top).
        self.assertEqual(axial.header["column"], [1, 0, 0])
        self.assertEqual(axial.header["row"], [0, 1, 0])
        self.assertEqual(coronal.header["row"], [0, 0, -1])
        # The default point is the volume's centre: the pixel at the image centre shows it.
        dims, spacing, origin = (state["volume"][k] for k in ("dims", "spacing", "origin"))
        centre = [origin[i] + (dims[i] - 1) * spacing[i] / 2 for i in range(3)]
        shown = axial.world_at((axial.width - 1) / 2, (axial.height - 1) / 2)
        for i in range(3):
            self.assertAlmostEqual(shown[i], centre[i], delta=axial.header["pixel_spacing"])

    def test_measurements_probe_roi_pick_and_a_slab(self):
        # A picked 3D point lies on material (the probe there finds the value the transfer
        # function makes opaque), an ROI's statistics bracket its mean, a slab's header says
        # how many planes it took, and a ray beside the volume picks nothing.
        async def body():
            async with await self.connect() as client:
                state = await open_demo(client)
                await client.send(vc.transfer_function({"points": GREY_RAMP}))
                await client.send(vc.camera(axis_camera(state, +1)))
                hit = await client.pick(SIZE / 2, SIZE / 2, SIZE, SIZE, timeout=60)
                miss = await client.pick(0.5, 0.5, SIZE, SIZE, timeout=60)
                at_hit = await client.probe(hit["point"], timeout=60) if hit["hit"] else None
                v = state["volume"]
                centre = [v["origin"][i] + (v["dims"][i] - 1) * v["spacing"][i] / 2 for i in range(3)]
                roi = await client.roi_stats("axial", centre, [10, 6], timeout=60)
                outside = await client.probe([c + 1e4 for c in centre], timeout=60)
                slab = await client.request_slice("axial", 32, 32, slab=vc.slab(4, "mean"), timeout=60)
                return state, hit, miss, at_hit, roi, outside, slab

        state, hit, miss, at_hit, roi, outside, slab = run(body())
        self.assertTrue(hit["hit"], hit)
        self.assertGreaterEqual(hit["opacity"], 0.5)
        self.assertTrue(at_hit["inside"])
        self.assertIsNone(at_hit["unit"], "the demo phantom is not in Hounsfield units")
        self.assertGreater(at_hit["value"], 0, "the picked point is on empty space (value 0 is transparent)")
        self.assertFalse(miss["hit"])
        self.assertIsNone(miss["point"])
        self.assertGreater(roi["samples"], 0)
        self.assertLessEqual(roi["min"], roi["mean"])
        self.assertLessEqual(roi["mean"], roi["max"])
        self.assertGreaterEqual(roi["std"], 0)
        self.assertFalse(outside["inside"])
        self.assertIsNone(outside["value"])
        spacing = min(state["volume"]["spacing"])
        self.assertEqual(slab.slab["planes"], int(np.ceil(4 / (spacing / 2))) + 1)
        self.assertEqual(slab.slab["mode"], "mean")


if __name__ == "__main__":
    unittest.main()
