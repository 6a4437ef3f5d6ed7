#!/usr/bin/python3
"""Load: many scripted sessions dragging and resting at once, with a slow client and a
slowloris alongside; prints one table.

Each session opens a scan, then repeats: interaction_start, camera messages every 40–50 ms
for 1–2 s, interaction_end, rest 1–2 s (`--rest`). The slow client opens a session, asks for frames and
replies, and never reads; the slowloris trickles an HTTP upgrade request one byte at a time.
Neither may hurt the others: their figures are the table's.

    /usr/bin/python3 tests/soak/load.py                      # 32 sessions × 60 s
    /usr/bin/python3 tests/soak/load.py --sessions 4 --duration 10 --volume builtin:demo
    /usr/bin/python3 tests/soak/load.py --no-slow-clients --rest 3,4   # final frames within 3 s of a rest?

Exit status 0 only if no well-behaved session got an error and the server survived and
exited 0 on SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import socket
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "client", "python"))
import volcast as vc  # noqa: E402

from rawws import RawWebSocket, frame_bytes, OP_TEXT  # noqa: E402
from scripted import DragSession  # noqa: E402
import serverproc  # noqa: E402


async def slow_client(host: str, port: int, volume: str, stop_at: float) -> str:
    """Open a session, then keep asking (camera changes, get_state) without ever reading."""
    ws = await RawWebSocket.connect(host, port)
    sock = ws.writer.get_extra_info("socket")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)   # fill the window soon
    await ws.send_text(vc.dumps(vc.hello(client="load slow client", id=1)).encode())
    await ws.send_text(vc.dumps(vc.open_volume(volume, id=2)).encode())
    base = {"eye": [600, 500, 700], "target": [127.5, 127.5, 127.5], "up": [0, 1, 0],
            "projection": "perspective", "fov_y_deg": 30}
    sent, write_blocked_at, n = 0, None, 2
    while time.monotonic() < stop_at:
        n += 1
        message = vc.camera(vc.orbit_camera(base, n * 5.0), id=n) if n % 2 else vc.get_state(id=n)
        ws.writer.write(frame_bytes(OP_TEXT, vc.dumps(message).encode()))
        try:
            await asyncio.wait_for(ws.writer.drain(), 1.0)
            sent += 1
        except asyncio.TimeoutError:
            write_blocked_at = write_blocked_at or time.monotonic()
        except ConnectionError:
            break
        await asyncio.sleep(0.1)
    # Now read what the server left for it: how much came, and whether it closed the session.
    frames = texts = 0
    outcome = "still open at the end"
    try:
        while True:
            kind, _ = await asyncio.wait_for(ws.receive(), 5.0)
            frames += kind == "binary"
            texts += kind == "text"
    except asyncio.TimeoutError:
        pass
    except Exception as e:   # Closed or ConnectionLost: how the server ended it
        outcome = str(e)
    ws.abort()
    return (f"sent {sent} requests without reading; afterwards it could read {frames} frames and "
            f"{texts} texts; {outcome}")


async def slowloris(host: str, port: int, stop_at: float, interval_s: float) -> str:
    """Trickle an endless HTTP upgrade request's headers, one byte per interval."""
    reader, writer = await asyncio.open_connection(host, port)
    start = time.monotonic()
    header = (f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n").encode()
    filler = b"X-Slow: " + b"a" * 100000
    data = header + filler
    sent = 0
    try:
        while time.monotonic() < stop_at and sent < len(data):
            writer.write(data[sent:sent + 1])
            await writer.drain()
            sent += 1
            try:  # the server's answer (a status line, or the end of the connection)
                got = await asyncio.wait_for(reader.read(4096), interval_s)
                if not got:
                    return f"the server closed the connection after {time.monotonic() - start:.1f} s ({sent} bytes sent)"
                first = got.split(b"\r\n", 1)[0].decode(errors="replace")
                return f"the server answered {first!r} after {time.monotonic() - start:.1f} s ({sent} bytes sent)"
            except asyncio.TimeoutError:
                pass
    except ConnectionError as e:
        return f"the connection was reset after {time.monotonic() - start:.1f} s ({sent} bytes sent): {e}"
    finally:
        writer.close()
    return f"still open at the end, {time.monotonic() - start:.1f} s ({sent} bytes sent)"


def pick_volumes(args) -> list:
    if args.volume:
        return [v.strip() for v in args.volume.split(",")]
    if os.path.isdir(args.data):
        return ["bonsai.nhdr"]
    print(f"note: {args.data} is absent; every session opens builtin:demo")
    return ["builtin:demo"]


async def load(args) -> int:
    volumes = pick_volumes(args)
    extra = ["--log-level", "warn", "--max-sessions", str(args.sessions + 4)]
    if os.path.isdir(args.data):
        extra += ["--data", args.data]
    load_before = serverproc.loadavg()
    server = serverproc.Server(args.server, extra) if args.port is None else None
    host, port = (server.host, server.port) if server else (args.host, args.port)
    try:
        rss_ready = server.rss_kib() if server else None
        # One session first loads each volume and waits for its final frame: loading and the
        # first kernel compilations are not what the table measures.
        for v in volumes:
            warm = DragSession("warm-up", host, port, v, random.Random(0), drag_s=(0.2, 0.2), rest_s=(0.0, 0.0),
                               wait_final=True, final_timeout_s=300.0, max_drags=1)
            ws = await warm.run(time.monotonic() + 600)
            if ws.errors or not ws.final_frames:
                print(f"warm-up on {v}: no final frame ({ws.errors[:3]})")
        rss_start = server.rss_kib() if server else None
        start = time.monotonic()
        stop_at = start + args.duration
        rng = random.Random(args.seed)
        sessions = [DragSession(f"s{i + 1:02d}", host, port, volumes[i % len(volumes)],
                                random.Random(rng.getrandbits(32)), drag_s=(1.0, 2.0), rest_s=args.rest,
                                camera_ms=(40.0, 50.0), wait_final=False, viewport=(512, 512))
                    for i in range(args.sessions)]
        tasks = [asyncio.create_task(s.run(stop_at)) for s in sessions]
        side = []
        if args.slow_clients:
            side.append(asyncio.create_task(slow_client(host, port, volumes[0], stop_at)))
            side.append(asyncio.create_task(slowloris(host, port, stop_at, args.slowloris_interval)))
        results = await asyncio.gather(*tasks)
        elapsed = time.monotonic() - start
        side_results = await asyncio.gather(*side, return_exceptions=True)
        rss_end = server.rss_kib() if server else None
        alive = server.alive() if server else True
        load_after = serverproc.loadavg()
        exit_code, exit_s, shutdown_closes = (await serverproc.stop_with_sessions_open(server, None)
                                                if server and alive else (server.stop() + ([],) if server else (None, 0.0, [])))
    finally:
        tail = server.log_tail() if server else ""
        if server:
            server.cleanup()

    print(f"\nvolcast load: {args.sessions} sessions × {args.duration:.0f} s ({elapsed:.1f} s wall), "
          f"volume {', '.join(volumes)}, 512×512, seed {args.seed}; load average before {load_before}, "
          f"after {load_after}")
    print(f"{'session':8} {'frames':>6} {'final':>5} {'drags':>5} {'cams':>5} {'p50 ms':>8} {'p95 ms':>8} "
          f"{'errors':>6} {'unshown':>7}")
    all_lat = []
    for st in results:
        all_lat += st.latencies_ms
        print(f"{st.name:8} {st.frames:6d} {st.final_frames:5d} {st.drags:5d} {st.cameras:5d} "
              f"{serverproc.percentile(st.latencies_ms, 50):8.0f} {serverproc.percentile(st.latencies_ms, 95):8.0f} "
              f"{len(st.errors):6d} {st.unshown:7d}")
    frames = [st.frames for st in results]
    errors = sum(len(st.errors) for st in results)
    reached = sum(1 for st in results if st.final_frames > 0)
    print(f"frames per session       min {min(frames)}, median {statistics.median(frames):.0f}, max {max(frames)}, "
          f"total {sum(frames)} ({sum(frames) / elapsed:.1f}/s)")
    print(f"motion-to-frame, all     p50 {serverproc.percentile(all_lat, 50):.0f} ms, p95 "
          f"{serverproc.percentile(all_lat, 95):.0f} ms ({len(all_lat)} cameras shown, "
          f"{sum(st.unshown for st in results)} never shown)")
    # The same over the run, by the time each camera was sent: where the slow frames fall.
    spans = {}
    for st in results:
        for sent, ms in zip(st.latency_sent, st.latencies_ms):
            spans.setdefault(int((sent - start) // 10), []).append(ms)
    print("motion-to-frame by 10 s   " + ", ".join(
        f"{10 * k}–{10 * k + 10} s p95 {serverproc.percentile(v, 95):.0f} ms" for k, v in sorted(spans.items())))
    p50s = sorted(serverproc.percentile(st.latencies_ms, 50) for st in results if st.latencies_ms)
    if p50s:
        print(f"per-session p50 spread   min {p50s[0]:.0f} ms, median {statistics.median(p50s):.0f} ms, "
              f"max {p50s[-1]:.0f} ms")
    print(f"reached a final frame    {reached} of {len(results)} sessions "
          f"({sum(st.final_frames for st in results)} final frames in all)")
    # A rest shorter than the bound that ended without its final frame says nothing about the bound.
    judged = [(t, n, f) for st in results for t, n, f in st.rests if f is not None or n >= args.final_within]
    late = sorted((t - start, f) for t, _, f in judged if f is None or f > args.final_within)
    waits = [f for _, _, f in judged if f is not None]
    every = sum(1 for st in results
                if all(f is not None and f <= args.final_within for _, n, f in st.rests
                       if f is not None or n >= args.final_within))
    print(f"final within {args.final_within:g} s of rest {len(judged) - len(late)} of {len(judged)} rests; "
          f"{every} of {len(results)} sessions every time" +
          (f"; rest to final p50 {serverproc.percentile(waits, 50) * 1000:.0f} ms, "
           f"p95 {serverproc.percentile(waits, 95) * 1000:.0f} ms, max {max(waits) * 1000:.0f} ms" if waits else ""))
    if late:
        print("late rests (s into the run: s to the final frame, - for none) " +
              ", ".join(f"{t:.1f}: {'-' if f is None else f'{f:.1f}'}" for t, f in late))
    dragging_s = sum(st.render_ms_dragging for st in results) / 1000.0
    resting_s = sum(st.render_ms_resting for st in results) / 1000.0
    print(f"render time of the frames shown: {dragging_s:.1f} s while dragging, {resting_s:.1f} s while resting, "
          f"in {elapsed:.1f} s")
    print(f"errors                   {errors}")
    if server:
        print(f"server RSS               ready {rss_ready / 1024:.1f} MiB, after warm-up (start) "
              f"{rss_start / 1024:.1f} MiB, end {(rss_end or 0) / 1024:.1f} MiB")
        print(f"SIGTERM                  exit code {exit_code}, {exit_s * 1000:.0f} ms to exit with "
              f"{len(shutdown_closes)} sessions open (one rendering); their closes: {', '.join(shutdown_closes)}")
    if args.slow_clients:
        for name, r in zip(("slow client", "slowloris"), side_results):
            print(f"{name:24} {r}")
    failures = []
    for st in results:
        for e in st.errors[:3]:
            print(f"error in {st.name}: {e}")
    if errors:
        failures.append(f"{errors} errors in well-behaved sessions")
    if not alive:
        failures.append("the server died")
        print(tail)
    if server and exit_code != 0:
        failures.append(f"SIGTERM exit code {exit_code}")
    if any(c != "1001" for c in shutdown_closes):
        failures.append(f"SIGTERM: open sessions got closes {shutdown_closes}, not 1001 (server/README.md)")
    if any(not st.opened for st in results):
        failures.append("a session could not open its volume")
    if failures:
        print("FAILED: " + "; ".join(failures))
        return 1
    print("OK")
    return 0


def seconds_range(text: str) -> tuple:
    low, _, high = text.partition(",")
    low, high = float(low), float(high or low)
    if not 0 <= low <= high:
        raise argparse.ArgumentTypeError(f"{text!r}: want MIN,MAX seconds with 0 <= MIN <= MAX")
    return low, high


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default=serverproc.DEFAULT_SERVER)
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, help="use a running server instead of starting one")
    p.add_argument("--data", default=serverproc.DEFAULT_DATA)
    p.add_argument("--volume", help="comma-separated; sessions take them in turn "
                                    "(default bonsai.nhdr, builtin:demo without the data folder)")
    p.add_argument("--sessions", type=int, default=32)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--rest", type=seconds_range, default=(1.0, 2.0), metavar="MIN,MAX",
                   help="seconds each rest lasts, drawn between MIN and MAX (default 1,2)")
    p.add_argument("--final-within", type=float, default=3.0, metavar="S",
                   help="the bound a rest's final frame is judged by: rests at least this long, or "
                        "whose final frame came, count (default 3)")
    p.add_argument("--no-slow-clients", dest="slow_clients", action="store_false",
                   help="leave out the slow client and the slowloris")
    p.add_argument("--slowloris-interval", type=float, default=0.5, help="seconds between its bytes")
    args = p.parse_args()
    return asyncio.run(load(args))


if __name__ == "__main__":
    sys.exit(main())
