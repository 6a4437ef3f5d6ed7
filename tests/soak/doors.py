"""The doors a user brings a scan through, attacked while another user drags.

Starts a real volcast-server on loopback with a fake PACS of its own (an HTTP server in this
process that answers what each attack needs: a search that hangs, a retrieval that trickles,
a Content-Type that reflects the credentials it was sent) and one session dragging the demo
volume, a new camera every 33 ms, for the whole run. Then, one after another:

  held-uploads     8 header-only POSTs claiming 64 MiB from 4 addresses (together the whole store), each fed 1 byte every
                   2 s, while a kept upload waits and a fifth address uploads a small file
  gzip-expansion   4 gzip NRRDs of ~130 KB that each expand to 134 MB, under a 512 MiB store
  chunked          a chunked body past the store's limit
  drip             an upload fed 1 byte a second
  bzip2-bomb       a 132-byte bzip2 NRRD claiming 1024 x 1024 x 680 floats (2.7 GiB)
  zip-bomb         a zip whose one entry unpacks to 512 MiB of zeros
  trickle          two retrievals from a PACS that sends 2 KiB a second, then a local open
  slow-search      a search of a PACS that hangs, then a search of another source
  many-searches    40 sessions searching at once
  reflection       a PACS that reflects the Authorization value it was sent

For each it prints the drag's largest gap between frames while the attack ran, what the
attackers and the bystanders were answered, and the figures the guarantees are about: the
server's resident memory (peak over its idle level), a local open's time, the searches'
waits, whether the kept upload survived, whether a credential reached a client or the log.
It is a measurement, not a test: it exits 0 whatever the figures, 1 only when the server
died or a run could not be made. Every loop is bounded in count and time.

    python3 tests/soak/doors.py                   # build/server/volcast-server
    python3 tests/soak/doors.py --only trickle,bzip2-bomb
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import bz2
import gzip
import http.server
import io
import json
import os
import socket
import socketserver
import sys
import tempfile
import threading
import time
import urllib.parse
import zipfile
from typing import Callable, Dict, List, Optional, Tuple

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rawws import Closed, ConnectionLost, RawWebSocket  # noqa: E402
from scripted import vc  # noqa: E402  (the Python client's messages and frame decoder)
from serverproc import DEFAULT_SERVER, Server, rss_kib  # noqa: E402

STUDY = "1.2.826.0.1.3680043.8.498.1"
SERIES = "1.2.826.0.1.3680043.8.498.2"
PACS_USER, PACS_PASSWORD = "volcast", "s3cret-Passw0rd"
CREDENTIAL = "Basic " + base64.b64encode(f"{PACS_USER}:{PACS_PASSWORD}".encode()).decode()
# Each form of the credential a careless server could quote (docs/data-sources.md).
CREDENTIAL_FORMS = [CREDENTIAL, CREDENTIAL.split(" ", 1)[1], f"{PACS_USER}:{PACS_PASSWORD}", PACS_PASSWORD,
                    urllib.parse.quote(CREDENTIAL, safe=""), urllib.parse.quote(PACS_PASSWORD, safe="")]


# --- the fake PACS --------------------------------------------------------------------------

class Pacs:
    """One HTTP server with a source per path prefix: /fast answers at once, /slow hangs
    searches and trickles retrievals, /echo reflects the Authorization value it was sent in
    each answer's Content-Type. `stop` ends every hanging answer."""

    def __init__(self) -> None:
        self.stop = threading.Event()
        self.requests: List[str] = []
        pacs = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args) -> None:   # quiet
                pass

            def do_GET(self) -> None:
                pacs.requests.append(self.path)
                try:
                    pacs.answer(self)
                except (BrokenPipeError, ConnectionResetError):
                    pass

        class Threaded(socketserver.ThreadingMixIn, http.server.HTTPServer):
            daemon_threads = True

        self.httpd = Threaded(("127.0.0.1", 0), Handler)
        self.port = self.httpd.server_address[1]
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def url(self, source: str) -> str:
        return f"http://127.0.0.1:{self.port}/{source}"

    def close(self) -> None:
        self.stop.set()
        self.httpd.shutdown()

    @staticmethod
    def _json(handler, body, content_type="application/dicom+json") -> None:
        data = json.dumps(body).encode()
        handler.send_response(200)
        handler.send_header("Content-Type", content_type)
        handler.send_header("Content-Length", str(len(data)))
        handler.end_headers()
        handler.wfile.write(data)

    def answer(self, h) -> None:
        path = urllib.parse.urlsplit(h.path).path
        source, _, rest = path.lstrip("/").partition("/")
        auth = h.headers.get("Authorization", "")
        content_type = "application/dicom+json"
        if source == "echo":
            # A type the client refuses, so that its error has a reason to quote it.
            decoded = base64.b64decode(auth.split(" ", 1)[-1] or "").decode(errors="replace")
            content_type = f"text/plain; sent={auth}; decoded={decoded}; encoded={urllib.parse.quote(auth, safe='')}"
        parts = rest.split("/")
        if rest == "studies":
            if source == "slow":
                self.stop.wait(25)   # a search that hangs for longer than the server waits
            elif source == "fast":
                time.sleep(0.2)      # a PACS that takes a moment for every search
            study = {"0020000D": {"vr": "UI", "Value": [STUDY]}, "00100010": {"vr": "PN", "Value": [{"Alphabetic": "DOE^JANE"}]},
                     "00100020": {"vr": "LO", "Value": ["P-1"]}, "00080020": {"vr": "DA", "Value": ["20240101"]}}
            return self._json(h, [study], content_type)
        if len(parts) == 3 and parts[2] == "series":
            series = {"0020000E": {"vr": "UI", "Value": [SERIES]}, "00080060": {"vr": "CS", "Value": ["CT"]},
                      "00201209": {"vr": "IS", "Value": [64]}}
            return self._json(h, [series], content_type)
        if len(parts) == 5 and parts[4] == "instances":
            instance = {"00280010": {"vr": "US", "Value": [64]}, "00280011": {"vr": "US", "Value": [64]}}
            return self._json(h, [instance] * 64, content_type)
        if len(parts) == 4 and parts[2] == "series" and source == "echo":
            body = (f"--B\r\nContent-Type: {content_type}\r\n\r\n".encode() + bytes(64) + b"\r\n--B--\r\n")
            h.send_response(200)
            h.send_header("Content-Type", f'multipart/related; type="application/dicom"; boundary=B; x="{auth}"')
            h.send_header("Content-Length", str(len(body)))
            h.end_headers()
            h.wfile.write(body)
            return
        if len(parts) == 4 and parts[2] == "series":
            # WADO-RS: a multipart body that trickles 2 KiB a second (above the client's 1 KiB/s
            # low-speed limit, so only the load's own time limit or our stop ends it).
            h.send_response(200)
            h.send_header("Content-Type", 'multipart/related; type="application/dicom"; boundary=B')
            h.end_headers()
            h.wfile.write(b"--B\r\nContent-Type: application/dicom\r\n\r\n")
            h.wfile.flush()
            for _ in range(120):
                if self.stop.wait(0.5):
                    break
                h.wfile.write(b"\0" * 1024)
                h.wfile.flush()
            return
        h.send_response(404)
        h.send_header("Content-Length", "0")
        h.end_headers()


# --- HTTP uploads from chosen addresses ------------------------------------------------------

def connect_from(address: str, port: int, timeout: float = 30.0) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout)
    s.bind((address, 0))
    s.connect(("127.0.0.1", port))
    return s


def read_answer(s: socket.socket) -> Tuple[int, str]:
    data = b""
    try:
        while b"\r\n\r\n" not in data or len(data) < 4096:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
            head, sep, body = data.partition(b"\r\n\r\n")
            if sep:
                length = next((int(line.split(b":", 1)[1]) for line in head.split(b"\r\n")
                               if line.lower().startswith(b"content-length:")), None)
                if length is not None and len(body) >= length:
                    break
    except (socket.timeout, ConnectionResetError):
        pass
    head, _, body = data.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1]) if head.startswith(b"HTTP/") else 0
    return status, body.decode(errors="replace").strip()


def upload(port: int, name: str, body: bytes, address: str = "127.0.0.1", chunked: bool = False) -> Tuple[int, str]:
    with connect_from(address, port) as s:
        head = (f"POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Volcast-Filename: {name}\r\n"
                + ("Transfer-Encoding: chunked\r\n" if chunked else f"Content-Length: {len(body)}\r\n") + "\r\n")
        s.sendall(head.encode())
        try:
            if chunked:
                step = 1 << 20
                for at in range(0, len(body), step):
                    piece = body[at:at + step]
                    s.sendall(f"{len(piece):x}\r\n".encode() + piece + b"\r\n")
                s.sendall(b"0\r\n\r\n")
            else:
                s.sendall(body)
        except (BrokenPipeError, ConnectionResetError):
            pass
        return read_answer(s)


def nrrd(sizes: Tuple[int, int, int], type_: str, data: bytes, encoding: str = "raw") -> bytes:
    header = (f"NRRD0004\ntype: {type_}\ndimension: 3\nsizes: {sizes[0]} {sizes[1]} {sizes[2]}\n"
              f"spacings: 1 1 1\nencoding: {encoding}\nendian: little\n\n")
    return header.encode() + data


def small_nrrd() -> bytes:
    """About 125 KB: a 40 x 40 x 40 int16 ramp."""
    return nrrd((40, 40, 40), "short", b"".join(int(i % 1000).to_bytes(2, "little", signed=True) for i in range(40 ** 3)))


# --- the dragging bystander and WebSocket sessions -------------------------------------------

class Dragger:
    """A session dragging the demo volume without rest: a camera every 33 ms; the arrival
    time of every frame is kept."""

    def __init__(self, port: int):
        self.port = port
        self.frame_times: List[float] = []
        self.errors: List[str] = []
        self.stop = False

    async def run(self) -> None:
        ws = await RawWebSocket.connect("127.0.0.1", self.port)
        await ws.send_text(vc.dumps(vc.hello(client="doors dragger", id=1)).encode())
        await ws.send_text(vc.dumps(vc.viewport(512, 512, id=2)).encode())
        await ws.send_text(vc.dumps(vc.open_volume("builtin:demo", id=3)).encode())
        base = None
        while base is None:
            kind, data = await ws.receive()
            if kind == "text":
                m = json.loads(data)
                if m.get("type") == "state":
                    base = m["scene"]["camera"]

        async def reader():
            try:
                while True:
                    kind, data = await ws.receive()
                    if kind == "binary":
                        self.frame_times.append(time.monotonic())
                    else:
                        m = json.loads(data)
                        if m.get("type") == "error":
                            self.errors.append(f"{m.get('code')}: {m.get('message')}")
            except (Closed, ConnectionLost) as e:
                if not self.stop:
                    self.errors.append(f"connection ended: {e}")

        task = asyncio.create_task(reader())
        await ws.send_text(vc.dumps(vc.interaction_start(id=4)).encode())
        angle, n = 0.0, 10
        while not self.stop:
            angle += 2.0
            n += 1
            await ws.send_text(vc.dumps(vc.camera(vc.orbit_camera(base, angle), id=n)).encode())
            await asyncio.sleep(0.033)
        await ws.close()
        task.cancel()

    def largest_gap_ms(self, start: float, end: float) -> float:
        times = [t for t in self.frame_times if start <= t <= end]
        edges = [start] + times + [end]
        return max(b - a for a, b in zip(edges, edges[1:])) * 1000.0


async def session_request(port: int, message: dict, answer_types: Tuple[str, ...], timeout: float = 60.0) -> Tuple[dict, float]:
    """A new session sends one request; (its answer, seconds from sending to the answer)."""
    ws = await RawWebSocket.connect("127.0.0.1", port)
    try:
        await ws.send_text(vc.dumps(vc.hello(client="doors", id=1)).encode())
        start = None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            kind, data = await asyncio.wait_for(ws.receive(), max(0.1, deadline - time.monotonic()))
            if kind != "text":
                continue
            m = json.loads(data)
            if m.get("type") == "hello":
                start = time.monotonic()
                await ws.send_text(vc.dumps(message).encode())
            elif m.get("id") == message.get("id") and (m.get("type") in answer_types or m.get("type") == "error"):
                return m, time.monotonic() - start
        return {"type": "timeout"}, timeout
    finally:
        await ws.close()


class RssWatch:
    """The server's resident memory sampled every 10 ms while an attack runs."""

    def __init__(self, pid: int):
        self.pid, self.peak, self.done = pid, 0, threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.done.wait(0.01):
            self.peak = max(self.peak, rss_kib(self.pid) or 0)

    def finish(self) -> int:
        self.done.set()
        self.thread.join()
        return self.peak


# --- the attacks -----------------------------------------------------------------------------

class Run:
    def __init__(self, server: Server, pacs: Pacs, upload_dir: str, data_dir: str):
        self.server, self.pacs, self.upload_dir, self.data_dir = server, pacs, upload_dir, data_dir
        self.port = server.port
        self.victim: Optional[str] = None
        self.bodies: Dict[str, bytes] = {}

    # Bodies that take seconds to make are made before their attack's window, off the event
    # loop that the dragging session's frames arrive on.
    PREPARED = {"gzip-expansion": "expanding_nrrd", "bzip2-bomb": "bzip2_nrrd", "zip-bomb": "zip_of_zeros",
                "chunked": "over_the_store"}

    @staticmethod
    def over_the_store() -> bytes:
        return nrrd((512, 512, 640), "float", bytes(512 * 512 * 640 * 4))   # 640 MiB over a 512 MiB store

    async def prepare(self, name: str) -> None:
        if name in self.PREPARED and name not in self.bodies:
            self.bodies[name] = await asyncio.to_thread(getattr(self, self.PREPARED[name]))

    async def ensure_victim(self) -> List[str]:
        status, body = await asyncio.to_thread(upload, self.port, "victim.nrrd", small_nrrd(), "127.0.0.9")
        if status == 201:
            self.victim = json.loads(body)["volume"]
            return ["victim kept: 201"]
        return [f"victim upload: {status} {body[:120]}"]

    async def victim_still_opens(self) -> str:
        if not self.victim:
            return "no victim"
        answer, _ = await session_request(self.port, vc.open_volume(self.victim, id=7), ("state",))
        return "victim still opens" if answer.get("type") == "state" else f"victim LOST: {answer.get('code')} {answer.get('message')}"

    async def held_uploads(self) -> List[str]:
        notes = await self.ensure_victim()
        sockets = []
        for i in range(8):
            s = connect_from(f"127.0.0.{2 + i % 4}", self.port)
            s.sendall(f"POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1:{self.port}\r\nX-Volcast-Filename: big{i}.nrrd\r\n"
                      f"Content-Length: {64 << 20}\r\n\r\n".encode())   # 8 x 64 MiB: the whole 512 MiB store
            sockets.append(s)

        async def drip():
            for _ in range(4):
                await asyncio.sleep(2)
                for s in sockets:
                    try:
                        s.send(b"N")
                    except OSError:
                        pass

        dripping = asyncio.create_task(drip())
        await asyncio.sleep(1)
        status, body = await asyncio.to_thread(upload, self.port, "bystander.nrrd", small_nrrd(), "127.0.0.6")
        notes.append(f"bystander's upload during the attack: {status} {body[:100]}")
        await dripping
        cut = 0
        for s in sockets:
            s.setblocking(False)
            try:
                cut += s.recv(1) == b""
            except BlockingIOError:
                pass
            except OSError:
                cut += 1
            s.close()
        notes.append(f"held requests closed by the server after 9 s: {cut} of 8")
        notes.append(await self.victim_still_opens())
        return notes

    @staticmethod
    def expanding_nrrd() -> bytes:
        return nrrd((512, 512, 128), "float", gzip.compress(bytes(512 * 512 * 128 * 4), 9), "gzip")

    async def gzip_expansion(self) -> List[str]:
        notes = [] if self.victim else await self.ensure_victim()
        body = self.bodies["gzip-expansion"]
        notes.append(f"each body {len(body)} bytes, {512 * 512 * 128 * 4 >> 20} MiB parsed")
        statuses = []
        for i in range(4):
            status, text = await asyncio.to_thread(upload, self.port, f"expand{i}.nrrd", body, "127.0.0.7")
            statuses.append(f"{status}" + ("" if status == 201 else f" ({text[:80]})"))
        notes.append("answers: " + ", ".join(statuses))
        notes.append(await self.victim_still_opens())
        return notes

    async def chunked(self) -> List[str]:
        body = self.bodies["chunked"]
        peak = {"bytes": 0}
        done = threading.Event()

        def watch():
            while not done.wait(0.05):
                total = 0
                for root, _, files in os.walk(self.upload_dir):
                    for f in files:
                        try:
                            total += os.path.getsize(os.path.join(root, f))
                        except OSError:
                            pass
                peak["bytes"] = max(peak["bytes"], total)

        t = threading.Thread(target=watch, daemon=True)
        t.start()
        status, text = await asyncio.to_thread(upload, self.port, "chunked.nrrd", body, "127.0.0.8", True)
        done.set()
        t.join()
        return [f"answer {status} {text[:100]}", f"upload folder's peak size {peak['bytes'] / 2**20:.0f} MiB (store limit 512)",
                await self.victim_still_opens()]

    async def drip(self) -> List[str]:
        s = connect_from("127.0.0.10", self.port)
        s.sendall(f"POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1:{self.port}\r\nX-Volcast-Filename: drip.nrrd\r\n"
                  f"Content-Length: 100000\r\n\r\n".encode())
        start = time.monotonic()
        s.setblocking(False)
        answer = b""
        while time.monotonic() - start < 40:
            try:
                s.send(b"N")
            except OSError:
                break
            await asyncio.sleep(1)
            try:
                chunk = s.recv(4096)
                if chunk == b"":
                    break
                answer += chunk
            except BlockingIOError:
                pass
            except OSError:
                break
        s.close()
        took = time.monotonic() - start
        status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "none"
        return [f"cut after {took:.1f} s with status {status}" if took < 40 else "NOT cut within 40 s"]

    async def bomb(self, name: str, body: bytes) -> List[str]:
        pid = self.server.pid
        idle = rss_kib(pid) or 0
        watch = RssWatch(pid)
        status, text = await asyncio.to_thread(upload, self.port, name, body, "127.0.0.11")
        peak = watch.finish()
        return [f"body {len(body)} bytes; answer {status} {text[:140]}",
                f"server RSS idle {idle / 1024:.0f} MiB, peak during the upload {peak / 1024:.0f} MiB (+{(peak - idle) / 1024:.0f} MiB)"]

    @staticmethod
    def bzip2_nrrd() -> bytes:
        compressor = bz2.BZ2Compressor(9)
        zeros = bytes(1 << 22)
        data = b"".join(compressor.compress(zeros) for _ in range(1024 * 1024 * 680 * 4 // len(zeros))) + compressor.flush()
        return nrrd((1024, 1024, 680), "float", data, "bzip2")

    @staticmethod
    def zip_of_zeros() -> bytes:
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
            with z.open("slice.dcm", "w", force_zip64=True) as entry:
                zeros = bytes(1 << 22)
                for _ in range(128):
                    entry.write(zeros)
        return buffer.getvalue()

    async def bzip2_bomb(self) -> List[str]:
        return await self.bomb("bomb.nrrd", self.bodies["bzip2-bomb"])

    async def zip_bomb(self) -> List[str]:
        return await self.bomb("bomb.zip", self.bodies["zip-bomb"])

    async def trickle(self) -> List[str]:
        name = f"dicomweb:slow/{STUDY}/{SERIES}"
        retrievals = [asyncio.create_task(session_request(self.port, vc.open_volume(name, id=5), ("state",), 90))
                      for _ in range(2)]
        await asyncio.sleep(2)   # both under way
        answer, took = await session_request(self.port, vc.open_volume("local.nrrd", id=6), ("state",), 60)
        notes = [f"local open during two trickling retrievals: {took:.2f} s ({answer.get('type')})"]
        self.pacs.stop.set()     # end the trickles
        for r in retrievals:
            a, t = await r
            notes.append(f"a trickling retrieval ended after {t:.1f} s: {a.get('type')} {a.get('code', '')}")
        self.pacs.stop.clear()
        return notes

    async def slow_search(self) -> List[str]:
        hanging = asyncio.create_task(session_request(self.port, vc.find_studies("slow", id=5), ("studies",), 60))
        await asyncio.sleep(1)
        answer, took = await session_request(self.port, vc.find_studies("fast", id=6), ("studies",), 60)
        self.pacs.stop.set()
        a, t = await hanging
        self.pacs.stop.clear()
        return [f"search of another source while one hangs: {took:.2f} s ({answer.get('type')})",
                f"the hanging search: {a.get('type')} {a.get('code', '')} after {t:.1f} s"]

    async def many_searches(self) -> List[str]:
        results = await asyncio.gather(*[session_request(self.port, vc.find_studies("fast", id=5), ("studies",), 90)
                                         for _ in range(40)])
        busy = sum(1 for a, _ in results if a.get("code") == "busy")
        ok = sum(1 for a, _ in results if a.get("type") == "studies")
        slowest = max(t for _, t in results)
        return [f"40 searches: {ok} answered, {busy} busy, slowest {slowest:.1f} s"]

    async def reflection(self) -> List[str]:
        notes = []
        for message, kind in ((vc.find_studies("echo", id=5), "search"),
                              (vc.open_volume(f"dicomweb:echo/{STUDY}/{SERIES}", id=5), "open")):
            answer, _ = await session_request(self.port, message, ("studies", "state"), 60)
            text = json.dumps(answer)
            leaked = [f for f in CREDENTIAL_FORMS if f in text]
            notes.append(f"{kind}: {answer.get('type')} {answer.get('code', '')}; credential in the answer: "
                         + (", ".join(leaked) if leaked else "no"))
        log = open(self.server.log_path, encoding="utf-8", errors="replace").read()
        leaked = [f for f in CREDENTIAL_FORMS if f in log]
        notes.append("credential in the server's log: " + (", ".join(leaked) if leaked else "no"))
        return notes


ATTACKS: Dict[str, Callable[[Run], object]] = {
    "held-uploads": Run.held_uploads, "gzip-expansion": Run.gzip_expansion, "chunked": Run.chunked,
    "drip": Run.drip, "bzip2-bomb": Run.bzip2_bomb, "zip-bomb": Run.zip_bomb, "trickle": Run.trickle,
    "slow-search": Run.slow_search, "many-searches": Run.many_searches, "reflection": Run.reflection,
}


async def main_async(args) -> int:
    pacs = Pacs()
    work = tempfile.TemporaryDirectory(prefix="volcast-doors-")
    data_dir = os.path.join(work.name, "data")
    upload_dir = os.path.join(work.name, "uploads")
    os.makedirs(data_dir)
    with open(os.path.join(data_dir, "local.nrrd"), "wb") as f:
        f.write(small_nrrd())
    auth = os.path.join(work.name, "pacs.auth")
    with open(auth, "w") as f:
        f.write(CREDENTIAL + "\n")
    os.chmod(auth, 0o600)
    server_args = ["--data", data_dir, "--upload-dir", upload_dir, "--max-upload-storage-mib", "512",
                   "--max-sessions", "64",
                   "--dicomweb-timeout-s", "10", "--load-timeout-s", "60",
                   "--log-level", "debug", *args.server_arg]
    for source in ("fast", "slow", "echo"):
        server_args += ["--dicomweb", f"{source}={pacs.url(source)}", "--dicomweb-auth", f"{source}={auth}"]
    server = Server(args.server, server_args)
    run = Run(server, pacs, upload_dir, data_dir)
    dragger = Dragger(server.port)
    drag = asyncio.create_task(dragger.run())
    await asyncio.sleep(3)   # the drag under way
    rows = []
    status = 0
    try:
        for name in args.only:
            await run.prepare(name)
            start = time.monotonic()
            notes = await ATTACKS[name](run)
            end = time.monotonic()
            gap = dragger.largest_gap_ms(start, end)
            rows.append((name, end - start, gap, notes))
            print(f"{name}: {end - start:.1f} s, the drag's largest frame gap {gap:.0f} ms", flush=True)
            for n in notes:
                print(f"    {n}", flush=True)
            if not server.alive():
                print(f"the server died:\n{server.log_tail()}")
                status = 1
                break
    finally:
        dragger.stop = True
        await asyncio.wait_for(drag, 10)
        code, _ = server.stop()
        pacs.close()
    print("\n| attack | seconds | drag's largest frame gap (ms) | what happened |")
    print("|---|---:|---:|---|")
    for name, seconds, gap, notes in rows:
        print(f"| {name} | {seconds:.1f} | {gap:.0f} | {'; '.join(notes)} |")
    if dragger.errors:
        print("the dragging session was told: " + "; ".join(dragger.errors[:5]))
    server.cleanup()
    work.cleanup()
    return status


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--server", default=DEFAULT_SERVER)
    parser.add_argument("--only", default=",".join(ATTACKS), help="comma-separated attacks, in order")
    parser.add_argument("--server-arg", action="append", default=[], help="one more argument for the server")
    args = parser.parse_args()
    args.only = [a for a in args.only.split(",") if a]
    unknown = [a for a in args.only if a not in ATTACKS]
    if unknown:
        parser.error(f"unknown attacks {unknown}; known: {', '.join(ATTACKS)}")
    return asyncio.run(main_async(args))


if __name__ == "__main__":
    sys.exit(main())
