"""A well-behaved scripted session: open a volume, then drag (camera messages between
interaction_start and interaction_end), rest, repeat; measure what the user would see.

Motion-to-frame is the time from sending a camera message to the first frame whose
`request` is that message's id or a later one (latest wins: a camera replaced before it was
rendered is shown by the frame of its successor).
"""

from __future__ import annotations

import asyncio
import json
import os
import random
import sys
import time
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "client", "python"))
import volcast as vc  # noqa: E402

from rawws import Closed, ConnectionLost, RawWebSocket  # noqa: E402


@dataclass
class DragStats:
    name: str
    volume: str = ""
    frames: int = 0
    final_frames: int = 0
    cameras: int = 0
    drags: int = 0
    latencies_ms: List[float] = field(default_factory=list)
    latency_sent: List[float] = field(default_factory=list)  # when each latency's camera went (time.monotonic())
    errors: List[str] = field(default_factory=list)
    rests_without_final: int = 0      # rests that ended before the view's final frame came
    longest_gap_s: float = 0.0        # longest time without a frame while the session wanted one
    opened: bool = False
    unshown: int = 0                  # cameras no frame showed by the end
    # Per rest: (its start, time.monotonic(); its length; seconds from interaction_end to the
    # final frame of the view it rested on, or None where the rest ended, or the run stopped,
    # before that frame came).
    rests: List[Tuple[float, float, Optional[float]]] = field(default_factory=list)
    render_ms_dragging: float = 0.0   # the headers' render_ms of the frames that came while dragging
    render_ms_resting: float = 0.0    # … and while resting


class DragSession:
    """Drives one session until `stop_at` (time.monotonic()). Timings come from `rng`:
    drag_s and rest_s are (min, max) ranges, camera_ms the interval range between cameras.
    With wait_final, a rest lasts until the final frame comes (at most final_timeout_s)."""

    def __init__(self, name: str, host: str, port: int, volume: str, rng: random.Random,
                 drag_s=(1.0, 2.0), rest_s=(1.0, 2.0), camera_ms=(40.0, 50.0),
                 wait_final: bool = False, final_timeout_s: float = 30.0, viewport=(512, 512),
                 max_drags: Optional[int] = None, token: Optional[str] = None):
        self.stats = DragStats(name, volume)
        self.host, self.port, self.volume, self.rng = host, port, volume, rng
        self.drag_s, self.rest_s, self.camera_ms = drag_s, rest_s, camera_ms
        self.wait_final, self.final_timeout_s, self.viewport = wait_final, final_timeout_s, viewport
        self.max_drags = max_drags
        self.token = token
        self.pending = {}                 # camera id -> send time, until a frame shows it
        self.last_frame_at = 0.0
        self.final_for: Optional[int] = None   # request id of the newest final frame
        self.final_event = asyncio.Event()
        self.replies: asyncio.Queue = asyncio.Queue()
        self.ws: Optional[RawWebSocket] = None
        self.next_id = 1
        self.closed_by_us = False
        self.rest_open: Optional[tuple] = None   # (last camera id, interaction_end time) of the rest under way
        self.rest_final_s: Optional[float] = None

    def _id(self) -> int:
        self.next_id += 1
        return self.next_id

    async def _send(self, message: dict) -> None:
        await self.ws.send_text(vc.dumps(message).encode())

    async def _reader(self) -> None:
        try:
            while True:
                kind, data = await self.ws.receive()
                now = time.monotonic()
                if kind == "binary":
                    try:
                        frame = vc.decode_frame(data)
                    except vc.FrameError as e:
                        self.stats.errors.append(f"bad frame: {e}")
                        continue
                    self.stats.frames += 1
                    self.last_frame_at = now
                    if self.rest_open:
                        self.stats.render_ms_resting += frame.header.get("render_ms", 0.0)
                    else:
                        self.stats.render_ms_dragging += frame.header.get("render_ms", 0.0)
                    request = frame.header.get("request")
                    if isinstance(request, int):
                        for cid in [c for c in self.pending if c <= request]:
                            sent = self.pending.pop(cid)
                            self.stats.latencies_ms.append((now - sent) * 1000.0)
                            self.stats.latency_sent.append(sent)
                    if frame.header["final"]:
                        self.stats.final_frames += 1
                        self.final_for = request
                        self.final_event.set()
                        if (self.rest_open and self.rest_final_s is None and isinstance(request, int)
                                and request >= self.rest_open[0]):
                            self.rest_final_s = now - self.rest_open[1]
                    continue
                message = json.loads(data.decode("utf-8"))
                if message.get("type") == "error":
                    self.stats.errors.append(f"{message.get('code')}: {message.get('message')}")
                if message.get("type") != "progress":
                    await self.replies.put(message)
        except Closed as e:
            if not self.closed_by_us:
                self.stats.errors.append(f"closed by the server: {e.code} {e.reason}")
        except ConnectionLost as e:
            if not self.closed_by_us:
                self.stats.errors.append(f"connection lost: {e}")
        await self.replies.put(None)

    async def _reply(self, timeout: float = 60.0) -> dict:
        message = await asyncio.wait_for(self.replies.get(), timeout)
        if message is None:
            raise ConnectionLost("the connection ended while waiting for a reply")
        return message

    async def run(self, stop_at: float) -> DragStats:
        self.stop_at = stop_at   # the caller may move it while the session runs
        try:
            self.ws = await RawWebSocket.connect(self.host, self.port)
        except (OSError, ConnectionLost, asyncio.TimeoutError) as e:
            self.stats.errors.append(f"connect: {e}")
            return self.stats
        reader = asyncio.create_task(self._reader())
        try:
            await self._session()
        except (ConnectionLost, ConnectionError, asyncio.TimeoutError) as e:
            self.stats.errors.append(f"{type(e).__name__}: {e}")
        finally:
            self.closed_by_us = True
            await self.ws.close()
            reader.cancel()
            try:
                await reader
            except asyncio.CancelledError:
                pass
        self.stats.unshown = len(self.pending)
        return self.stats

    async def _session(self) -> None:
        await self._send(vc.hello(token=self.token, client="volcast soak/load scripted session", id=1))
        if (await self._reply()).get("type") != "hello":
            return
        await self._send(vc.viewport(*self.viewport, id=self._id()))
        await self._send(vc.open_volume(self.volume, id=self._id()))
        state = await self._reply(timeout=300.0)
        if state.get("type") != "state":
            return
        self.stats.opened = True
        base = state["scene"]["camera"]
        angle = 0.0
        while time.monotonic() < self.stop_at and self.stats.drags != self.max_drags:
            self.stats.drags += 1
            await self._send(vc.interaction_start(id=self._id()))
            drag_end = min(self.stop_at, time.monotonic() + self.rng.uniform(*self.drag_s))
            while time.monotonic() < drag_end:
                angle += 3.0
                cid = self._id()
                self.pending[cid] = time.monotonic()
                self.stats.cameras += 1
                await self._send(vc.camera(vc.orbit_camera(base, angle), id=cid))
                await asyncio.sleep(self.rng.uniform(*self.camera_ms) / 1000.0)
            last_camera = self.next_id
            self.final_event.clear()
            rest_start = time.monotonic()
            self.rest_open, self.rest_final_s = (last_camera, rest_start), None
            await self._send(vc.interaction_end(id=self._id()))
            rest = self.rng.uniform(*self.rest_s)
            if self.wait_final:
                await self._wait_final(last_camera, self.final_timeout_s)
                await asyncio.sleep(max(0.0, rest - (time.monotonic() - rest_start)))
            else:
                await asyncio.sleep(min(rest, max(0.0, self.stop_at - time.monotonic())))
            if not (self.final_for is not None and self.final_for >= last_camera):
                self.stats.rests_without_final += 1
            self.stats.rests.append((rest_start, time.monotonic() - rest_start, self.rest_final_s))
            self.rest_open = None
            self.stats.longest_gap_s = max(self.stats.longest_gap_s, self._gap())

    def _gap(self) -> float:
        """Seconds the oldest camera not yet shown has waited (0 when all are shown)."""
        if not self.pending:
            return 0.0
        return time.monotonic() - min(self.pending.values())

    async def _wait_final(self, request: int, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not (self.final_for is not None and self.final_for >= request):
            left = deadline - time.monotonic()
            if left <= 0:
                return
            self.final_event.clear()
            try:
                await asyncio.wait_for(self.final_event.wait(), left)
            except asyncio.TimeoutError:
                return
