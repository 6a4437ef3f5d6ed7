#!/usr/bin/env python3
"""Refinement at rest on a real server: one client opens a scan at a viewport, rests, and
records every frame of the view: the final frame, then each pass at rest (rest_pass) with
its estimated error and when it came, until the server stops sending (its target of half a
grey level, or --rest-refinement-s). With --drag, a second client drags meanwhile, and
its motion-to-frame latency is printed for the --window-s after the resting view's final
frame and for the time after that: refinement at rest must not delay it (compare with
--rest-s 0).

    python3 tests/bench/rest_refinement.py [--server build/server/volcast-server]
        [--volume bonsai.nhdr] [--size 512] [--quiet-s 20] [--drag]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "soak"))
sys.path.insert(0, os.path.join(HERE, "..", "..", "client", "python"))

import serverproc  # noqa: E402
import volcast as vc  # noqa: E402


def rgb_rmse(a, b) -> float:
    """RMSE over RGB in [0, 1] composited over black (the server's error metric): a PNG frame
    holds straight colour and alpha."""
    import numpy

    def over_black(x):
        x = x.astype(numpy.float64) / 255
        return x[..., :3] * x[..., 3:4]
    d = over_black(a) - over_black(b)
    return float(numpy.sqrt(numpy.mean(d * d)))


async def resting_client(url: str, volume: str, size: int, quiet_s: float, check_step: float) -> list:
    rows = []
    images = []
    async with await vc.Client.connect(url) as c:
        await c.open_volume(volume)
        await c.send(vc.viewport(size, size))
        state = await c.request(vc.get_state())
        camera = vc.orbit_camera(state["scene"]["camera"], 20.0)
        t0 = time.monotonic()
        last = await c.send(vc.camera(camera))
        final_seen = False
        while True:
            item = await c.receive(timeout=quiet_s if final_seen else 120)
            if item is None:
                break
            if not isinstance(item, vc.Frame) or item.request != last:
                continue
            final_seen = final_seen or item.final
            e = item.error or {}
            if item.final or item.rest_pass:
                images.append(item.to_numpy())

            rows.append({"at": time.monotonic(), "t_s": round(time.monotonic() - t0, 3), "level": item.level, "final": item.final,
                         "rest_pass": item.rest_pass, "step": item.header["quality"].get("step"),
                         "render_ms": round(item.header["render_ms"], 1), "error": e.get("value"),
                         "method": e.get("method")})
        if check_step:
            # The estimates against a frame far closer to the exact integral: the same view at
            # check_step without early termination (its own error is ~(check_step / step)²
            # of the pass at step's, below what is compared).
            quality = dict(state["scene"]["quality"], step=check_step, early_termination=1.0)
            rid = await c.send(vc.quality_explicit(quality))
            exact = await c.wait_for_final_frame(request=rid, timeout=600)
            truth = exact.to_numpy()

            shown = [r for r in rows if r["final"] or r["rest_pass"]]
            for r, img in zip(shown, images):
                r["rmse_vs_check"] = rgb_rmse(img, truth)
    return rows


async def dragging_client(url: str, volume: str, stop: asyncio.Event, latencies: list) -> None:
    async with await vc.Client.connect(url) as c:
        await c.open_volume(volume)
        await c.send(vc.viewport(512, 512))
        state = await c.request(vc.get_state())
        angle = 0.0
        while not stop.is_set():
            angle += 3
            sent = time.monotonic()
            rid = await c.send(vc.camera(vc.orbit_camera(state["scene"]["camera"], angle)))
            while True:
                item = await c.receive(timeout=10)
                if item is None:
                    break
                if isinstance(item, vc.Frame) and item.request == rid:
                    latencies.append((sent, (time.monotonic() - sent) * 1000))
                    break
            await asyncio.sleep(0.02)


async def run(args) -> int:
    server = serverproc.Server(args.server, ["--data", args.data, "--rest-refinement-s", str(args.rest_s)])
    try:
        url = f"ws://{server.host}:{server.port}/ws"
        stop, latencies = asyncio.Event(), []
        drag = asyncio.create_task(dragging_client(url, args.volume, stop, latencies)) if args.drag else None
        if drag:
            await asyncio.sleep(5)   # the drag's own frames before the rest begins
        rows = await resting_client(url, args.volume, args.size, args.quiet_s, args.check_step)
        stop.set()
        if drag:
            await drag
    finally:
        server.stop()
    print(f"{args.volume}, {args.size}², --rest-refinement-s {args.rest_s}; load average {os.getloadavg()[0]:.1f}")
    print(f"| t (s) | frame | step | render (ms) | estimated error | grey levels | method | RMSE against step {args.check_step} |")
    print("|---:|---|---:|---:|---:|---:|---|---:|")
    for r in rows:
        kind = f"pass {r['rest_pass']} at rest" if r["rest_pass"] else ("final" if r["final"] else f"level {r['level']}")
        err = r["error"]
        print(f"| {r['t_s']} | {kind} | {r['step']} | {r['render_ms']} | "
              f"{'–' if err is None else f'{err:.2e}'} | {'–' if err is None else f'{err * 255:.2f}'} | {r['method'] or '–'} | "
              f"{('%.2e' % r['rmse_vs_check']) if 'rmse_vs_check' in r else '–'} |")
    if args.drag:
        # In the --window-s after the resting view's final frame (where its passes at rest run,
        # if any: compare with --rest-s 0) and after that, when the drag is alone.
        final_at = next(r["at"] for r in rows if r["final"])
        during = sorted(ms for at, ms in latencies if final_at <= at <= final_at + args.window_s)
        after = sorted(ms for at, ms in latencies if at > final_at + args.window_s + 1)
        p = lambda v, q: v[min(len(v) - 1, int(q * len(v)))] if v else float("nan")  # noqa: E731
        print(f"drag motion-to-frame in the {args.window_s:g} s after the other view's final frame: p50 {p(during, .5):.0f} ms, "
              f"p95 {p(during, .95):.0f} ms ({len(during)} frames); after it: p50 {p(after, .5):.0f} ms, "
              f"p95 {p(after, .95):.0f} ms ({len(after)} frames)")
    for r in rows:
        del r["at"]
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows, "drag_latencies_ms": latencies}, f, indent=1)
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default=serverproc.DEFAULT_SERVER)
    p.add_argument("--data", default=serverproc.DEFAULT_DATA)
    p.add_argument("--volume", default="bonsai.nhdr")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--rest-s", type=float, default=10, help="the server's --rest-refinement-s")
    p.add_argument("--quiet-s", type=float, default=20, help="seconds without a frame that end the record")
    p.add_argument("--drag", action="store_true", help="a second client drags meanwhile")
    p.add_argument("--window-s", type=float, default=2, help="--drag: the window after the final frame")
    p.add_argument("--check-step", type=float, default=0.0625,
                   help="after the rest, render the view at this step without early termination and measure "
                        "the final frame and each pass against it (0: no check)")
    p.add_argument("--json", help="write the rows here")
    return asyncio.run(run(p.parse_args()))


if __name__ == "__main__":
    sys.exit(main())
