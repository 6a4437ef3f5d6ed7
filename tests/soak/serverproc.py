"""Start a real volcast-server on loopback, watch its memory, stop it with SIGTERM.

Shared by soak.py, load.py and tests/protocol/python_live. The server's log goes to a file whose tail is printed when
the server dies or misbehaves, so a failure explains itself.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import tempfile
import time
from typing import List, Optional

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
DEFAULT_SERVER = os.path.join(REPO, "build", "server", "volcast-server")
# The real scans stay outside the repository: VOLCAST_DATA_DIR names their folder (as for
# CMake), else the default beside the checkout (tests/CMakeLists.txt).
DEFAULT_DATA = os.environ.get("VOLCAST_DATA_DIR") or os.path.join(REPO, "..", "shared", "data", "volumes")


def rss_kib(pid: int) -> Optional[int]:
    """Resident memory of a process in KiB (VmRSS of /proc/PID/status), None once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def http_get(host: str, port: int, path: str, timeout: float = 5.0) -> tuple:
    """(status, body) of one plain HTTP/1.1 GET."""
    with socket.create_connection((host, port), timeout=timeout) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nConnection: close\r\n\r\n".encode())
        data = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1]) if head.startswith(b"HTTP/") else 0
    return status, body


class Server:
    """A volcast-server child process on 127.0.0.1 with a free port."""

    def __init__(self, exe: str, extra_args: List[str], ready_timeout: float = 120.0):
        if not os.access(exe, os.X_OK):
            raise SystemExit(f"server executable {exe} not found or not executable; build it with "
                             "`cmake --build build --target volcast-server` or pass --server")
        self.dir = tempfile.TemporaryDirectory(prefix="volcast-soak-")
        self.port_file = os.path.join(self.dir.name, "port")
        self.log_path = os.path.join(self.dir.name, "server.log")
        self.log = open(self.log_path, "wb")
        self.args = [exe, "--port", "0", "--port-file", self.port_file, *extra_args]
        self.proc = subprocess.Popen(self.args, stdout=self.log, stderr=subprocess.STDOUT)
        self.host = "127.0.0.1"
        self.port = self._wait_ready(ready_timeout)

    def _wait_ready(self, timeout: float) -> int:
        deadline = time.monotonic() + timeout
        port = None
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise SystemExit(f"server exited with {self.proc.returncode} while starting:\n{self.log_tail()}")
            if port is None:
                try:
                    with open(self.port_file) as f:
                        text = f.read().strip()
                    port = int(text) if text else None
                except (OSError, ValueError):
                    port = None
            if port is not None:
                try:
                    if http_get(self.host, port, "/readyz")[0] == 200:
                        return port
                except OSError:
                    pass
            time.sleep(0.1)
        self.proc.kill()
        raise SystemExit(f"server not ready within {timeout:.0f} s:\n{self.log_tail()}")

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def rss_kib(self) -> Optional[int]:
        return rss_kib(self.proc.pid)

    def log_tail(self, lines: int = 30) -> str:
        self.log.flush()
        try:
            with open(self.log_path, "rb") as f:
                text = f.read().decode("utf-8", errors="replace")
        except OSError:
            return "(no log)"
        return "\n".join("    " + line for line in text.splitlines()[-lines:])

    def stop(self, timeout: float = 20.0) -> tuple:
        """SIGTERM; (exit code or None if it had to be killed, seconds to exit). A server that
        was already gone reports its exit code and 0 s."""
        if self.proc.poll() is not None:
            return self.proc.returncode, 0.0
        start = time.monotonic()
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            return None, time.monotonic() - start
        return code, time.monotonic() - start

    def cleanup(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.log.close()
        self.dir.cleanup()


def render_summary(host: str, port: int) -> str:
    """What the render worker did, from /metrics: frames written, render time, stale drops."""
    try:
        status, body = http_get(host, port, "/metrics")
    except OSError as e:
        return f"(no /metrics: {e})"
    values = {}
    for line in body.decode(errors="replace").splitlines():
        if line.startswith("#") or " " not in line:
            continue
        name, _, value = line.rpartition(" ")
        base = name.split("{", 1)[0]
        try:
            values[base] = values.get(base, 0.0) + float(value)
        except ValueError:
            pass
    frames = values.get("volcast_frames_total", 0)
    render_s = values.get("volcast_render_seconds_sum", 0)
    renders = values.get("volcast_render_seconds_count", 0)
    stale = values.get("volcast_frames_dropped_stale_total", 0)
    return (f"{frames:.0f} frames written, {renders:.0f} renders taking {render_s:.1f} s in all "
            f"({1000 * render_s / max(renders, 1):.0f} ms mean), {stale:.0f} dropped as stale")


async def stop_with_sessions_open(server: "Server", token=None, sessions: int = 3) -> tuple:
    """SIGTERM while sessions are open (one of them rendering): (exit code, seconds to exit,
    the close codes those sessions got). server/README.md: each gets 1001, exit 0 within ~2 s."""
    import asyncio
    import sys as _sys
    _sys.path.insert(0, os.path.join(REPO, "client", "python"))
    import volcast as vc
    from rawws import Closed, ConnectionLost, RawWebSocket

    open_ws = []
    for i in range(sessions):
        ws = await RawWebSocket.connect(server.host, server.port)
        await ws.send_text(vc.dumps(vc.hello(token=token, client="shutdown check", id=1)).encode())
        await asyncio.wait_for(ws.receive(), 30)
        if i == 0:   # one session busy rendering when the signal comes
            await ws.send_text(vc.dumps(vc.open_volume("builtin:demo", id=2)).encode())
        open_ws.append(ws)

    async def close_code(ws):
        try:
            while True:
                await asyncio.wait_for(ws.receive(), 25)
        except Closed as e:
            return str(e.code)
        except ConnectionLost:
            return "no close frame"
        except asyncio.TimeoutError:
            return "still open"

    await asyncio.sleep(0.3)
    readers = [asyncio.create_task(close_code(ws)) for ws in open_ws]
    code, seconds = await asyncio.get_running_loop().run_in_executor(None, server.stop)
    codes = await asyncio.gather(*readers)
    for ws in open_ws:
        ws.abort()
    return code, seconds, codes


def loadavg() -> str:
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


def percentile(values: List[float], p: float) -> float:
    """Nearest-rank percentile (p in [0, 100]); nan for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    rank = max(1, min(len(ordered), int(-(-p * len(ordered) // 100))))
    return ordered[rank - 1]
