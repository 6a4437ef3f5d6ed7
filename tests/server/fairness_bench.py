#!/usr/bin/python3
"""N sessions dragging the demo volume at once against a running volcast-server.

Each session: hello, open builtin:demo, wait for its first frame; then all at the same moment
interaction_start, then a
closed-loop drag (a new camera as soon as the previous camera's frame arrived) for
DRAG_SECONDS, then interaction_end and the time to its final frame. Prints one line of
p50/p95 motion-to-frame (ms, over the sessions' frames), frames per session (min/mean/max),
and time to final (median/max). Bounded: every wait has a timeout.

usage: fairness_bench.py PORT N [DRAG_SECONDS]
"""
import asyncio, json, math, statistics, struct, sys, time

import websockets


def header(data):
    n = struct.unpack("<I", data[4:8])[0]
    return json.loads(data[8:8 + n])


def camera(angle):
    c = [63.5, 63.5, 63.5]
    r = 420.0
    return {"eye": [c[0] + r * math.cos(angle), c[1] + 150, c[2] + r * math.sin(angle)],
            "target": c, "up": [0, 1, 0], "projection": "perspective", "fov_y_deg": 30}


async def until(ws, pred, timeout):
    end = time.monotonic() + timeout
    while True:
        msg = await asyncio.wait_for(ws.recv(), max(0.01, end - time.monotonic()))
        if isinstance(msg, bytes) and pred(header(msg)):
            return header(msg)


async def session(port, index, drag_seconds, start_at, out):
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws", max_size=None) as ws:
        await ws.send(json.dumps({"type": "hello", "id": 1, "protocol": 1, "client": "fairness_bench"}))
        await ws.send(json.dumps({"type": "open_volume", "id": 2, "name": "builtin:demo"}))
        await until(ws, lambda h: True, 300)   # open: its first frame (not its final: all drag at once)
        await asyncio.sleep(max(0, start_at - time.monotonic()))
        await ws.send(json.dumps({"type": "interaction_start", "id": 3}))
        latencies, rid, stop = [], 10, time.monotonic() + drag_seconds
        while time.monotonic() < stop:
            rid += 1
            t = time.monotonic()
            await ws.send(json.dumps({"type": "camera", "id": rid, "camera": camera(0.02 * rid + index)}))
            await until(ws, lambda h, r=rid: h.get("request") == r, 60)
            latencies.append((time.monotonic() - t) * 1e3)
        t = time.monotonic()
        await ws.send(json.dumps({"type": "interaction_end", "id": rid + 1}))
        await until(ws, lambda h: h.get("final"), 300)
        out[index] = (latencies, (time.monotonic() - t) * 1e3)


async def main():
    port, n = int(sys.argv[1]), int(sys.argv[2])
    drag = float(sys.argv[3]) if len(sys.argv) > 3 else 10
    out = {}
    start_at = time.monotonic() + 5 + 0.5 * n
    await asyncio.gather(*(session(port, i, drag, start_at, out) for i in range(n)))
    lat = sorted(x for l, _ in out.values() for x in l)
    frames = [len(l) for l, _ in out.values()]
    finals = sorted(f for _, f in out.values())
    q = lambda v, p: v[min(len(v) - 1, int(p * (len(v) - 1) + 0.5))]
    print(f"| {n} | {q(lat, 0.5):.0f} | {q(lat, 0.95):.0f} | {min(frames)} / {statistics.mean(frames):.1f} / {max(frames)} "
          f"| {statistics.median(finals) / 1e3:.1f} / {finals[-1] / 1e3:.1f} |")


asyncio.run(main())
