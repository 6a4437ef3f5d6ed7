#!/usr/bin/env python3
"""One WebSocket session against a running volcast server, as container_test.sh needs it.

    session_check.py ws://HOST:PORT/ws [--volume NAME] [--stop 'COMMAND' --grace S]

Says hello, checks that NAME (default: the default volume, builtin:demo) is listed, opens it
and waits for the final frame of its starting view (a PNG). With --stop, it then keeps the
session open, runs COMMAND (which should send SIGTERM to the server: `podman stop ...`) and
checks that the server closes the session with WebSocket close 1001 ("going away", the reason
naming SIGTERM) and that COMMAND returns within S seconds. Prints one JSON line of figures;
exits non-zero, naming what failed, otherwise. Uses the volcast package
(client/python/volcast) and Debian's python3-websockets.
"""

import argparse
import asyncio
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "client", "python"))
import volcast as vc  # noqa: E402

GOING_AWAY = 1001
FINAL_FRAME_TIMEOUT_S = 180  # s: the first frame of a fresh container compiles PoCL kernels


async def check(args) -> dict:
    figures = {}
    t0 = time.monotonic()
    client = await vc.Client.connect(args.url, client_name="container_test")
    try:
        listed = await client.request(vc.list_volumes(), timeout=30)
        names = [v["name"] for v in listed["volumes"]]
        if args.volume not in names:
            raise AssertionError(f"volume {args.volume!r} not listed; the server lists {names}")
        state = await client.request(vc.open_volume(args.volume), timeout=120)
        await client.send(vc.viewport(args.size, args.size))
        last = await client.send(vc.camera(state["scene"]["camera"]))
        frame = await client.wait_for_final_frame(request=last, timeout=FINAL_FRAME_TIMEOUT_S)
        if frame.codec != "png" or not frame.image.startswith(b"\x89PNG\r\n\x1a\n"):
            raise AssertionError(f"the final frame is not a PNG (codec {frame.codec})")
        figures.update(volume=args.volume, device=client.server_hello["device"]["name"],
                       final_frame_s=round(time.monotonic() - t0, 2), final_frame_bytes=len(frame.image),
                       size=[frame.width, frame.height])
        if not args.stop:
            return figures

        # Drain: the session stays open while the server is stopped; it must be told why.
        t_stop = time.monotonic()
        stopper = await asyncio.create_subprocess_shell(args.stop)
        close = None
        try:
            while await client.receive(timeout=args.grace) is not None:
                pass
            raise AssertionError(f"the session was not closed within {args.grace} s of the stop")
        except AssertionError:
            raise
        except Exception as e:  # websockets.ConnectionClosed; the library is imported lazily
            close = getattr(e, "rcvd", None)
            if close is None and not type(e).__name__.startswith("ConnectionClosed"):
                raise
        figures["session_closed_after_s"] = round(time.monotonic() - t_stop, 2)
        rc = await asyncio.wait_for(stopper.wait(), timeout=args.grace + 5)
        figures["stopped_after_s"] = round(time.monotonic() - t_stop, 2)
        if rc != 0:
            raise AssertionError(f"the stop command failed (exit {rc})")
        if close is None or close.code != GOING_AWAY or "SIGTERM" not in close.reason:
            got = f"{close.code} {close.reason!r}" if close else "no close frame"
            raise AssertionError(f"expected close {GOING_AWAY} naming SIGTERM, got {got}")
        figures.update(close_code=close.code, close_reason=close.reason)
        if figures["stopped_after_s"] > args.grace:
            raise AssertionError(f"stopping took {figures['stopped_after_s']} s, over the {args.grace} s grace period")
        return figures
    finally:
        try:
            await client.close()
        except Exception:
            pass  # already closed by the server


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url")
    parser.add_argument("--volume", default="builtin:demo")
    parser.add_argument("--size", type=int, default=128, help="viewport side, px")
    parser.add_argument("--stop", help="shell command that sends SIGTERM to the server")
    parser.add_argument("--grace", type=float, default=10, help="s the stop may take")
    args = parser.parse_args()
    try:
        figures = asyncio.run(check(args))
    except Exception as e:
        print(f"session_check: FAILED: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
