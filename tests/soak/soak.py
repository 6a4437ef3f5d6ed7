#!/usr/bin/python3
"""Network soak: hostile sessions and one well-behaved session against a real server.

Starts volcast-server on loopback (or uses --host/--port), opens --sessions hostile sessions
that send --messages hostile messages in all (see hostile.py), each followed by a probe
(`get_state` with a fresh id) so that every answer is attributed to the message before the
probe; checks each answer is documented; meanwhile one session drags and rests and must
keep getting frames. At the end: the server must still run, and exit 0 on SIGTERM.

    /usr/bin/python3 tests/soak/soak.py --messages 2000 --seed 1
    /usr/bin/python3 tests/soak/soak.py --replay out/soak/mutation-3.frames --role hello

Exit status 0 only if nothing undocumented happened. Findings are saved as reproducers
(raw WebSocket frames, replayable with --replay) in --out.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import os
import random
import sys
import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "client", "python"))
import volcast as vc  # noqa: E402

from hostile import Generator, Hostile, strict_parse  # noqa: E402
from rawws import OP_TEXT, Closed, ConnectionLost, RawWebSocket, frame_bytes  # noqa: E402
from scripted import DragSession  # noqa: E402
import serverproc  # noqa: E402

DOCUMENTED_CODES = set(vc.ERROR_CODES) - {"internal"}   # `internal` is the server's word for a bug
ROLES = ("prehello", "hello", "volume")
ANSWER_TIMEOUT_S = 20.0
HELLO_DEADLINE_S = 10.0   # the server's --hello-timeout-ms: a connection without hello is then closed 1008


@dataclass
class Finding:
    session: int
    role: str
    index: int
    hostile: Hostile
    problem: str
    answers: List[str]


@dataclass
class Tally:
    sent: int = 0
    by_category: Dict[str, int] = field(default_factory=collections.Counter)
    codes: Dict[str, int] = field(default_factory=collections.Counter)
    replies: Dict[str, int] = field(default_factory=collections.Counter)
    closes: Dict[str, int] = field(default_factory=collections.Counter)
    frames: int = 0
    no_text_answer: int = 0
    reconnects: int = 0
    findings: List[Finding] = field(default_factory=list)
    crashed: bool = False


def check_text(data: bytes) -> tuple:
    """(message dict or None, problem or None) for one server text message."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        return None, f"server text is not valid UTF-8 ({e})"
    message = strict_parse(data)
    if not isinstance(message, dict):
        return None, f"server text is not one strict JSON object: {text[:200]!r}"
    kind = message.get("type")
    if kind not in vc.SERVER_TYPES:
        return message, f"server message of unknown type {kind!r}"
    if "id" not in message:
        return message, "server message without an id"
    if kind == "error":
        code = message.get("code")
        if code not in DOCUMENTED_CODES:
            return message, f"error code {code!r} ({message.get('message')!r})"
        if not isinstance(message.get("message"), str):
            return message, "error without a message text"
        if not (message.get("request_type") is None or isinstance(message.get("request_type"), str)):
            return message, "error whose request_type is neither a string nor null"
    return message, None


class HostileSession:
    def __init__(self, index: int, role: str, host: str, port: int, gen: Generator, count: int,
                 tally: Tally, server: Optional[serverproc.Server], deadline: float):
        self.index, self.role, self.host, self.port = index, role, host, port
        self.gen, self.count, self.tally, self.server, self.deadline = gen, count, tally, server, deadline
        self.ws: Optional[RawWebSocket] = None
        self.token: Optional[str] = None
        self.probe = 0

    async def _open(self) -> None:
        self.ws = await RawWebSocket.connect(self.host, self.port)
        self.connected_at = time.monotonic()
        self.hello_done = False
        if self.role == "prehello":
            return
        await self._call(vc.hello(token=self.token, client="soak hostile", id="setup-hello"), "setup-hello")
        self.hello_done = True
        if self.role == "volume":
            # A small viewport first: the soak is about answers, not about rendering load.
            await self._call(vc.viewport(96, 96, id="setup-viewport"), None)
            await self._call(vc.open_volume("builtin:demo", id="setup-open"), "setup-open")

    async def _call(self, message: dict, wait_id) -> None:
        await self.ws.send_text(vc.dumps(message).encode())
        if wait_id is None:
            return
        end = time.monotonic() + 120.0
        while True:
            kind, data = await asyncio.wait_for(self.ws.receive(), max(0.1, end - time.monotonic()))
            if kind == "text":
                reply = json.loads(data)
                if reply.get("id") == wait_id and reply.get("type") != "progress":
                    if reply.get("type") == "error":
                        raise RuntimeError(f"session setup refused: {reply}")
                    return

    async def run(self) -> None:
        sent = 0
        while sent < self.count and time.monotonic() < self.deadline and not self.tally.crashed:
            if self.ws is None:
                try:
                    await self._open()
                except (OSError, ConnectionLost, Closed, asyncio.TimeoutError) as e:
                    self._lost(f"could not open a session: {type(e).__name__}: {e}")
                    return
            h = self.gen.next()
            sent += 1
            self.tally.sent += 1
            self.tally.by_category[h.category] += 1
            await self._exchange(h, sent)
        if self.ws is not None:
            await self.ws.close()

    def _lost(self, problem: str) -> None:
        if self.server is not None and not self.server.alive():
            self.tally.crashed = True

    async def _exchange(self, h: Hostile, index: int) -> None:
        self.probe += 1
        probe_id = f"probe-{self.index}-{self.probe}"
        probe = frame_bytes(OP_TEXT, vc.dumps(vc.get_state(id=probe_id)).encode())
        ws = self.ws

        async def send():
            try:
                await ws.send_raw(b"".join(h.frames) + probe)
            except (ConnectionError, RuntimeError):
                pass   # the server closed while we wrote (over the limit): the close tells why

        writer = asyncio.create_task(send())
        answers: List[dict] = []
        shown: List[str] = []
        problems: List[str] = []
        closed: Optional[int] = None
        lost: Optional[str] = None
        answered = False
        end = time.monotonic() + ANSWER_TIMEOUT_S
        try:
            while not answered:
                kind, data = await asyncio.wait_for(ws.receive(), max(0.05, end - time.monotonic()))
                if kind == "binary":
                    try:
                        vc.decode_frame(data)
                        self.tally.frames += 1
                    except vc.FrameError as e:
                        problems.append(f"undecodable frame: {e}")
                    continue
                message, problem = check_text(data)
                shown.append(data[:300].decode("utf-8", errors="replace"))
                if problem:
                    problems.append(problem)
                if message is None:
                    continue
                if message.get("type") == "hello":
                    self.hello_done = True
                if message.get("id") == probe_id and message.get("type") != "progress":
                    answered = True
                elif message.get("type") != "progress":
                    answers.append(message)
        except Closed as e:
            closed = e.code
        except ConnectionLost as e:
            lost = str(e)
        except asyncio.TimeoutError:
            problems.append(f"no answer to the message or the probe after it within {ANSWER_TIMEOUT_S:.0f} s")
        writer.cancel()
        try:
            await writer
        except asyncio.CancelledError:
            pass

        for a in answers:
            if a.get("type") == "error":
                self.tally.codes[a["code"]] += 1
            else:
                self.tally.replies[a["type"]] += 1
        if not answers:
            self.tally.no_text_answer += 1
        codes = [a.get("code") for a in answers if a.get("type") == "error"]

        if closed is not None or lost is not None:
            self.tally.closes["no close frame" if lost is not None else str(closed)] += 1
            self.tally.reconnects += 1
            self.ws.abort()
            self.ws = None
            if lost is not None:
                alive = True
                if self.server is not None:
                    await asyncio.sleep(0.2)
                    alive = self.server.alive()
                if not alive:
                    self.tally.crashed = True
                    problems.append(f"connection dropped without a close frame ({lost}); "
                                    f"the server process exited ({self.server.proc.returncode})")
                elif h.may_drop:
                    self.tally.closes["no close frame"] -= 1
                    self.tally.closes["reset (over the WebSocket limit)"] += 1
                else:
                    problems.append(f"connection dropped without a close frame ({lost})")
            elif closed in h.expect_close or (closed == 1000 and h.may_close_normally):
                pass
            elif closed == 1008 and "unauthorized" in codes:
                pass
            elif (closed == 1008 and not self.hello_done and
                  time.monotonic() - self.connected_at >= HELLO_DEADLINE_S - 0.5):
                self.tally.closes["1008 (hello deadline)"] += 1
                self.tally.closes[str(closed)] -= 1
            elif h.expect_code and h.expect_code in codes:
                pass   # the documented error came, then a close (a later probe cannot matter)
            else:
                problems.append(f"closed with {closed} ({ws.close_reason!r}); documented here: "
                                f"{list(h.expect_close) or ([1000] if h.may_close_normally else 'no close')}"
                                + (f" or error {h.expect_code}" if h.expect_code else ""))
        elif answered:
            if h.expect_code:
                if h.expect_code not in codes:
                    problems.append(f"expected error {h.expect_code}, got {codes or 'no error'}")
            elif h.expect_close:
                problems.append(f"expected close {list(h.expect_close)}, the connection stayed open")
            elif h.needs_answer and not answers:
                problems.append("no answer (every bad message gets one)")
        if problems:
            self.tally.findings.append(Finding(self.index, self.role, index, h, "; ".join(problems), shown))


def save_reproducer(out: str, n: int, f: Finding) -> str:
    os.makedirs(out, exist_ok=True)
    stem = os.path.join(out, f"{f.hostile.category}-{n}")
    with open(stem + ".frames", "wb") as fh:
        fh.write(b"".join(f.hostile.frames))
    with open(stem + ".txt", "w") as fh:
        fh.write(f"role: {f.role}\ncategory: {f.hostile.category}\nnote: {f.hostile.note}\n"
                 f"problem: {f.problem}\npayload (first 2000 bytes): {f.hostile.payload[:2000]!r}\n"
                 f"answers: {json.dumps(f.answers, ensure_ascii=False)}\n"
                 f"replay: /usr/bin/python3 tests/soak/soak.py --replay {stem}.frames --role {f.role}\n")
    return stem


async def replay(args) -> int:
    """Send one saved message (raw frames) on a fresh session and print what comes back."""
    with open(args.replay, "rb") as fh:
        frames = fh.read()
    server = None
    if args.port is None:
        server = serverproc.Server(args.server, server_args(args))
        host, port = server.host, server.port
    else:
        host, port = args.host, args.port
    try:
        gen = Generator(random.Random(0))
        s = HostileSession(0, args.role, host, port, gen, 1, Tally(), server, time.monotonic() + 60)
        s.token = args.token
        await s._open()
        h = Hostile("replay", [frames], frames, needs_answer=True)
        await s._exchange(h, 1)
        for f in s.tally.findings:
            print(f"finding: {f.problem}")
            for a in f.answers:
                print(f"  answer: {a}")
        if not s.tally.findings:
            print("documented answer (nothing found)")
        if server is not None:
            await asyncio.sleep(0.5)
            print(f"server alive: {server.alive()}")
            if not server.alive():
                print(server.log_tail())
        return 1 if s.tally.findings else 0
    finally:
        if server is not None:
            server.cleanup()


def server_args(args) -> List[str]:
    extra = ["--log-level", "warn", "--max-sessions", str(args.sessions + 8)]
    if args.data and os.path.isdir(args.data):
        extra += ["--data", args.data]
    if args.token:
        extra += ["--token", args.token]
    return extra


async def soak(args) -> int:
    start_wall = time.monotonic()
    server = None
    if args.port is None:
        server = serverproc.Server(args.server, server_args(args))
        host, port = server.host, server.port
    else:
        host, port = args.host, args.port
    tally = Tally()
    rss = []
    rss_by_sent = []   # (messages sent so far, RSS KiB), one a second
    try:
        rss_start = server.rss_kib() if server else None
        deadline = time.monotonic() + args.time_limit
        good = DragSession("good", host, port, args.volume, random.Random(args.seed), drag_s=(1.0, 1.0),
                           rest_s=(0.3, 0.5), camera_ms=(45.0, 45.0), wait_final=True,
                           final_timeout_s=30.0, viewport=(512, 512), token=args.token)
        good_task = asyncio.create_task(good.run(deadline + 60))
        # The good session's first final frame comes before any hostile traffic: the first
        # renders compile the OpenCL kernels (seconds on PoCL), which is not what is measured.
        warm_end = time.monotonic() + 180
        while good.stats.final_frames == 0 and not good_task.done() and time.monotonic() < warm_end:
            await asyncio.sleep(0.1)
        good.stats.latencies_ms.clear()
        good.stats.latency_sent.clear()
        rss_warm = server.rss_kib() if server else None
        per = [args.messages // args.sessions + (1 if i < args.messages % args.sessions else 0)
               for i in range(args.sessions)]
        sessions = [HostileSession(i, ROLES[i % len(ROLES)], host, port,
                                   Generator(random.Random(args.seed * 1000003 + i), args.categories),
                                   per[i], tally, server,
                                   deadline) for i in range(args.sessions)]
        for s in sessions:
            s.token = args.token

        async def sample_rss():
            while True:
                if server:
                    value = server.rss_kib()
                    if value:
                        rss.append(value)
                        rss_by_sent.append((tally.sent, value))
                await asyncio.sleep(1.0)

        sampler = asyncio.create_task(sample_rss())
        progress_at = time.monotonic() + 10

        async def report_progress():
            nonlocal progress_at
            while True:
                await asyncio.sleep(10)
                print(f"  ... {tally.sent} messages sent, {len(tally.findings)} findings, "
                      f"good session {good.stats.frames} frames, server RSS "
                      f"{(server.rss_kib() or 0) // 1024 if server else '?'} MiB, load {serverproc.loadavg()}",
                      flush=True)

        reporter = asyncio.create_task(report_progress()) if args.progress else None
        hostile_start = time.monotonic()
        await asyncio.gather(*(s.run() for s in sessions))
        hostile_s = time.monotonic() - hostile_start
        good.stop_at = time.monotonic()
        good_stats = await good_task
        sampler.cancel()
        if reporter:
            reporter.cancel()
        rss_end = server.rss_kib() if server else None
        alive = server.alive() if server else True
        render_summary = serverproc.render_summary(host, port) if alive else "(server gone)"
        exit_code, exit_s, shutdown_closes = (await serverproc.stop_with_sessions_open(server, args.token)
                                                if server and alive else (server.stop() + ([],) if server else (None, 0.0, [])))
        load = serverproc.loadavg()
    finally:
        log_tail = server.log_tail() if server else ""
        if server:
            server.cleanup()

    # --- The table -------------------------------------------------------------------------
    failures = []
    print(f"\nvolcast soak: seed {args.seed}, {args.sessions} hostile sessions "
          f"({', '.join(ROLES)} in turn) + 1 well-behaved ({args.volume}), load average {load}")
    print(f"messages sent            {tally.sent} of {args.messages} in {hostile_s:.1f} s "
          f"({tally.sent / max(hostile_s, 1e-9):.0f}/s), each followed by a get_state probe")
    if tally.sent < args.messages:
        why = "the server died" if tally.crashed or not alive else f"the time limit of {args.time_limit:.0f} s"
        print(f"                         stopped early: {why}")
    print("by category              " + ", ".join(f"{k} {v}" for k, v in sorted(tally.by_category.items())))
    print("errors by code           " + (", ".join(f"{k} {v}" for k, v in sorted(tally.codes.items())) or "none"))
    print("other replies            " + (", ".join(f"{k} {v}" for k, v in sorted(tally.replies.items())) or "none")
          + f"; {tally.no_text_answer} messages with no text answer (valid scene changes, closes)")
    print("closes by code           " + (", ".join(f"{k} {v}" for k, v in sorted(tally.closes.items()) if v) or "none")
          + f" ({tally.reconnects} reconnects)")
    print(f"frames to hostile        {tally.frames}")
    print(f"server's renders         {render_summary}")
    print(f"undocumented answers     {len(tally.findings)}")
    print(f"server crashes           {1 if tally.crashed or not alive else 0}")
    lat = good_stats.latencies_ms
    print(f"good session             {good_stats.frames} frames, {good_stats.final_frames} final, "
          f"{good_stats.drags} drags, {good_stats.cameras} cameras, errors {len(good_stats.errors)}, "
          f"rests without a final frame {good_stats.rests_without_final}, cameras never shown {good_stats.unshown}")
    print(f"good motion-to-frame     p50 {serverproc.percentile(lat, 50):.1f} ms, p95 "
          f"{serverproc.percentile(lat, 95):.1f} ms, max {max(lat) if lat else float('nan'):.1f} ms "
          f"({len(lat)} cameras)")
    if server:
        print(f"server RSS               ready {rss_start / 1024:.1f} MiB, after warm-up {rss_warm / 1024:.1f} MiB, "
              f"peak {max(rss + [rss_start]) / 1024:.1f} MiB, end {(rss_end or 0) / 1024:.1f} MiB")
        print(f"SIGTERM                  exit code {exit_code}, {exit_s * 1000:.0f} ms to exit with "
              f"{len(shutdown_closes)} sessions open (one rendering); their closes: {', '.join(shutdown_closes)}")
    if rss_by_sent:
        marks = []
        for q in (0, 25, 50, 75, 100):
            target = tally.sent * q / 100
            sent, value = min(rss_by_sent, key=lambda sv: abs(sv[0] - target))
            marks.append(f"{sent} msgs {value / 1024:.1f}")
        print("server RSS over the run   " + ", ".join(marks) + " (MiB)")
    print(f"wall time                {time.monotonic() - start_wall:.1f} s")

    for n, f in enumerate(tally.findings):
        if n < args.show:
            print(f"\nUNDOCUMENTED #{n + 1}: session {f.session} ({f.role}), message {f.index}, "
                  f"{f.hostile.category} ({f.hostile.note}):\n  sent   {f.hostile.payload[:300]!r}"
                  f"\n  problem {f.problem}" + "".join(f"\n  answer {a}" for a in f.answers[:4]))
        if n < args.save:
            stem = save_reproducer(args.out, n + 1, f)
            if n < args.show:
                print(f"  saved  {stem}.frames")
    if tally.findings:
        failures.append(f"{len(tally.findings)} messages got undocumented answers (above)")
    if tally.crashed or not alive:
        failures.append("the server crashed (the messages in flight then are the findings that say "
                        "'the server process exited'; --replay each to find the one)")
        print("\nserver log tail:\n" + log_tail)
    if good_stats.errors:
        failures.append(f"the well-behaved session got errors: {good_stats.errors[:5]}")
    if not good_stats.opened or good_stats.frames == 0:
        failures.append("the well-behaved session got no frames")
    if good_stats.rests_without_final or good_stats.unshown:
        failures.append(f"the well-behaved session stalled: {good_stats.rests_without_final} rests without a "
                        f"final frame within 30 s, {good_stats.unshown} cameras never shown")
    if server and exit_code != 0:
        failures.append(f"SIGTERM: the server exited with {exit_code} (None: killed after 20 s)")
    if any(c != "1001" for c in shutdown_closes):
        failures.append(f"SIGTERM: open sessions got closes {shutdown_closes}, not 1001 (server/README.md)")
    if failures:
        print("\nFAILED: " + "; ".join(failures))
        return 1
    print("\nOK: every hostile message got a documented answer; the well-behaved session kept rendering")
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default=serverproc.DEFAULT_SERVER, help="volcast-server executable to start")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, help="use a running server instead of starting one")
    p.add_argument("--data", default=serverproc.DEFAULT_DATA, help="data folder for the started server (if present)")
    p.add_argument("--volume", default="builtin:demo", help="what the well-behaved session opens")
    p.add_argument("--messages", type=int, default=2000, help="hostile messages in all")
    p.add_argument("--sessions", type=int, default=6, help="hostile sessions")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--time-limit", type=float, default=600.0, help="seconds; hostile sending stops then")
    p.add_argument("--out", default=os.path.join(serverproc.REPO, "out", "soak"), help="where reproducers go")
    p.add_argument("--show", type=int, default=10, help="findings printed in full")
    p.add_argument("--save", type=int, default=50, help="findings saved as reproducers")
    p.add_argument("--progress", action="store_true", help="a line every 10 s")
    p.add_argument("--token", help="start the server with this access token (hostile hellos mostly lack it)")
    p.add_argument("--categories", help="comma-separated: only these kinds of message (hostile.py's names)")
    p.add_argument("--replay", help="send this saved .frames file on a fresh session and report")
    p.add_argument("--role", choices=ROLES, default="hello", help="session state for --replay")
    args = p.parse_args()
    if args.replay:
        return asyncio.run(replay(args))
    return asyncio.run(soak(args))


if __name__ == "__main__":
    sys.exit(main())
