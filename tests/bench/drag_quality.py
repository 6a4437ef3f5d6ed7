#!/usr/bin/python3
"""Drag quality: what a user dragging a volume sees, in time and in error.

One session opens a volume at a square viewport and drags it: a camera every --camera-ms,
each turned 3 degrees further about the view's up axis, between interaction_start and
interaction_end, for --drag-s seconds. Motion-to-frame per camera is measured as
tests/soak/scripted.py does (send time to the first frame whose request is that camera's or
a later one). Then --keep of the interactive frames, spread evenly over the drag after its
first --settle-s seconds (the ladder's timer has measured its levels by then), are compared
with the final frame of their own camera, asked for at rest: PSNR of the JPEG the user saw
against that PNG, both as 8-bit RGB over black (the protocol's composite for JPEG). That is
the interactive target (docs/service.md): p95 motion-to-frame <= 40 ms with frames >= 30 dB.

Runs with Debian's /usr/bin/python3 and its python3-numpy and python3-pil (frame decoding:
client/python/volcast/frames.py). A benchmark, not a test: run it on a quiet machine and
interleave builds (--server) when comparing them.

    /usr/bin/python3 tests/bench/drag_quality.py --server build/server/volcast-server \\
        --volume bonsai.nhdr --size 512 --drag-s 4 --json out.json
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "client", "python"))
sys.path.insert(0, os.path.join(HERE, "..", "soak"))
import numpy as np  # noqa: E402
import volcast as vc  # noqa: E402
import serverproc  # noqa: E402
from rawws import RawWebSocket  # noqa: E402


def over_black(frame: vc.Frame) -> np.ndarray:
    """The frame as 8-bit RGB over black, in float for the difference."""
    rgba = frame.to_numpy().astype(np.float64)
    if frame.header["codec"] == "png":   # premultiplied RGBA sent as straight: rgb·a is the composite
        return rgba[..., :3] * rgba[..., 3:4] / 255.0
    return rgba[..., :3]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(255.0 ** 2 / mse)


def percentile(values, p):
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(p / 100.0 * len(s)) - 1))] if s else math.nan


def level_name(quality: dict) -> str:
    return (f"scale {quality.get('image_scale', 1):g}, mip {quality.get('mip_level', 0)}, "
            f"step {quality.get('step', 1):g}")


class Session:
    def __init__(self, host: str, port: int):
        self.host, self.port = host, port
        self.frames = []          # (arrival time, Frame)
        self.replies: asyncio.Queue = asyncio.Queue()
        self.next_id = 1

    def id(self) -> int:
        self.next_id += 1
        return self.next_id

    async def send(self, message: dict) -> None:
        await self.ws.send_text(vc.dumps(message).encode())

    async def reader(self) -> None:
        while True:
            kind, data = await self.ws.receive()
            if kind == "binary":
                self.frames.append((time.monotonic(), vc.decode_frame(data)))
                continue
            message = json.loads(data.decode("utf-8"))
            if message.get("type") == "error":
                raise SystemExit(f"the server answered with an error: {message}")
            if message.get("type") != "progress":
                await self.replies.put(message)

    async def final_for(self, request: int, timeout: float = 60.0) -> vc.Frame:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for _, f in reversed(self.frames):
                if f.header.get("request") == request and f.header["final"]:
                    return f
            await asyncio.sleep(0.01)
        raise SystemExit(f"no final frame for request {request} within {timeout:.0f} s")


async def run(args, host: str, port: int) -> dict:
    s = Session(host, port)
    s.ws = await RawWebSocket.connect(host, port)
    reader = asyncio.create_task(s.reader())
    await s.send(vc.hello(client="volcast drag_quality", id=1))
    await asyncio.wait_for(s.replies.get(), 30)
    await s.send(vc.viewport(args.size, args.size, id=s.id()))
    await s.send(vc.open_volume(args.volume, id=s.id()))
    state = await asyncio.wait_for(s.replies.get(), 300)
    if state.get("type") != "state":
        raise SystemExit(f"open_volume {args.volume}: {state}")
    base = state["scene"]["camera"]
    await asyncio.sleep(args.rest_s)             # the first view's refinement ends

    sent = {}                                    # camera id -> send time
    await s.send(vc.interaction_start(id=s.id()))
    start = time.monotonic()
    angle = 0.0
    while time.monotonic() - start < args.drag_s:
        angle += 3.0
        cid = s.id()
        sent[cid] = time.monotonic()
        await s.send(vc.camera(vc.orbit_camera(base, angle), id=cid))
        await asyncio.sleep(args.camera_ms / 1000.0)
    drag_frames = [(t, f) for t, f in s.frames if isinstance(f.header.get("request"), int)
                   and f.header["request"] in sent and not f.header["final"]]
    await s.send(vc.interaction_end(id=s.id()))

    latencies = []
    for cid, t_sent in sent.items():
        shown = [t for t, f in s.frames if isinstance(f.header.get("request"), int) and f.header["request"] >= cid]
        if shown:
            latencies.append((min(shown) - t_sent) * 1000.0)
    levels = {}
    for _, f in drag_frames:
        name = level_name(f.header["quality"])
        levels[name] = levels.get(name, 0) + 1

    settled = [(t, f) for t, f in drag_frames if t - start >= args.settle_s]
    picks = [settled[round(i * (len(settled) - 1) / max(1, args.keep - 1))] for i in range(args.keep)] if settled else []
    kept = []
    for _, f in picks:
        await asyncio.sleep(0.2)
        cid = s.id()
        await s.send(vc.camera(f.header["camera"], id=cid))
        final = await s.final_for(cid)
        kept.append({"request": f.header["request"], "level": level_name(f.header["quality"]),
                     "render_ms": f.header["render_ms"], "psnr_db": psnr(over_black(f), over_black(final))})
    reader.cancel()
    await s.ws.close()
    return {
        "volume": args.volume, "size": args.size, "cameras": len(sent), "drag_frames": len(drag_frames),
        "motion_to_frame_ms": {"p50": percentile(latencies, 50), "p95": percentile(latencies, 95),
                               "unshown": len(sent) - len(latencies)},
        "levels": levels, "kept": kept,
        "psnr_db": {"min": min(k["psnr_db"] for k in kept) if kept else math.nan,
                    "mean": statistics.fmean(k["psnr_db"] for k in kept) if kept else math.nan},
        "load_average": os.getloadavg(),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--server", default=os.path.join(HERE, "..", "..", "build", "server", "volcast-server"))
    p.add_argument("--data", default=serverproc.DEFAULT_DATA)
    p.add_argument("--volume", default="bonsai.nhdr")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--drag-s", type=float, default=4.0)
    p.add_argument("--camera-ms", type=float, default=40.0)
    p.add_argument("--settle-s", type=float, default=1.0)
    p.add_argument("--rest-s", type=float, default=2.0)
    p.add_argument("--keep", type=int, default=5)
    p.add_argument("--json", help="write the result here too")
    args = p.parse_args()
    server = serverproc.Server(args.server, ["--data", args.data])
    try:
        result = asyncio.run(run(args, server.host, server.port))
    finally:
        server.stop()
    # Which build ran, without this machine's folders: the path inside the repository, or
    # the binary's folder and name.
    server = os.path.abspath(args.server)
    repo = os.path.abspath(os.path.join(HERE, "..", ".."))
    inside = os.path.commonpath([server, repo]) == repo
    result["server"] = os.path.relpath(server, repo) if inside else os.path.join(
        os.path.basename(os.path.dirname(server)), os.path.basename(server))
    m = result["motion_to_frame_ms"]
    print(f"{args.volume} {args.size}²: {result['cameras']} cameras, {result['drag_frames']} drag frames; "
          f"motion-to-frame p50 {m['p50']:.1f} ms, p95 {m['p95']:.1f} ms; "
          f"PSNR of {len(result['kept'])} kept frames min {result['psnr_db']['min']:.1f} dB, "
          f"mean {result['psnr_db']['mean']:.1f} dB; levels {result['levels']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
