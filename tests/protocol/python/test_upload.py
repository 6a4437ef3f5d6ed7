"""Client.upload and Client.open_array's HTTP side, offline: the request they make (POST
/api/volumes on the WebSocket URL's host and port, X-Volcast-Filename, the bearer token, the
file streamed with its Content-Length), the answer's volume name, and the UploadError of a
refusal. The server here is a small recording http.server on 127.0.0.1 that answers as the
test tells it; the real server's side is in ../python_live."""

import asyncio
import hashlib
import http.server
import json
import os
import socket
import tempfile
import threading
import unittest

import volcast as vc
from test_client import FakeSocket

try:
    import numpy as np
except ImportError:
    np = None

VOLUME = "upload:0123456789abcdef0123456789abcdef"
CREATED = (201, "application/json", json.dumps({"volume": VOLUME, "filename": "x", "bytes": 0,
                                                "expires_in_s": 3600}).encode())


class Recorder(http.server.BaseHTTPRequestHandler):
    """Records each request (method, target, headers, body digest and length) and answers
    with the server's `answer` (status, content type, body). With `read_body` false it answers
    before reading the body and closes, as a server refusing a Content-Length does."""

    protocol_version = "HTTP/1.1"

    def do_POST(self):
        srv = self.server
        record = {"method": "POST", "target": self.path, "headers": dict(self.headers.items()),
                  "header_names": [k.lower() for k in self.headers.keys()]}
        if srv.read_body:
            length = int(self.headers.get("Content-Length", "0"))
            digest, got, reads = hashlib.sha256(), 0, 0
            keep = bytearray()
            while got < length:
                chunk = self.rfile.read(min(1 << 16, length - got))
                if not chunk:
                    break
                digest.update(chunk)
                got += len(chunk)
                if len(keep) < srv.keep_bytes:
                    keep += chunk[:srv.keep_bytes - len(keep)]
            record.update(body_bytes=got, sha256=digest.hexdigest(), body_start=bytes(keep))
        srv.requests.append(record)
        status, content_type, body = srv.answer
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        if not srv.read_body:
            self.send_header("Connection", "close")
            self.close_connection = True
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


class RecordingServer:
    def __init__(self, answer=CREATED, read_body=True, keep_bytes=1 << 20):
        self.httpd = http.server.HTTPServer(("127.0.0.1", 0), Recorder)
        self.httpd.requests, self.httpd.answer = [], answer
        self.httpd.read_body, self.httpd.keep_bytes = read_body, keep_bytes
        self.port = self.httpd.server_address[1]
        self.url = f"ws://127.0.0.1:{self.port}/ws"
        # A short poll: shutdown() waits for it.
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.02,), daemon=True)
        self.thread.start()

    @property
    def requests(self):
        return self.httpd.requests

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 30))


class UploadTests(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="volcast-upload-")
        self.addCleanup(self.tmp.cleanup)

    def file_of(self, name, size):
        path = os.path.join(self.tmp.name, name)
        data = os.urandom(size)
        with open(path, "wb") as f:
            f.write(data)
        return path, data

    def test_upload_posts_the_file_to_the_websocket_servers_host_and_port(self):
        path, data = self.file_of("head ct.nii.gz", 3 * (1 << 20) + 17)
        progress = []
        with RecordingServer() as server:
            client = vc.Client(FakeSocket([]), url=server.url, token="s3cret")
            name = run(client.upload(path, on_progress=lambda sent, total: progress.append((sent, total))))
            (request,) = server.requests
        self.assertEqual(name, VOLUME)
        self.assertEqual((request["method"], request["target"]), ("POST", "/api/volumes"))
        headers = request["headers"]
        self.assertEqual(headers["X-Volcast-Filename"], "head ct.nii.gz")
        self.assertEqual(headers["Authorization"], "Bearer s3cret")
        self.assertEqual(headers["Host"], f"127.0.0.1:{server.port}")
        self.assertEqual(headers["Content-Length"], str(len(data)))
        self.assertNotIn("transfer-encoding", request["header_names"])
        self.assertEqual((request["body_bytes"], request["sha256"]), (len(data), hashlib.sha256(data).hexdigest()))
        # Streamed a MiB at a time, and the callback ran for each piece, the last at the total.
        self.assertEqual(progress, [(1 << 20, len(data)), (2 << 20, len(data)), (3 << 20, len(data)),
                                    (len(data), len(data))])

    def test_no_token_no_authorization_header_and_a_name_can_be_given(self):
        path, _ = self.file_of("scan.bin", 10)
        with RecordingServer() as server:
            run(vc.Client(FakeSocket([]), url=server.url).upload(path, filename="scan.mha"))
            (request,) = server.requests
        self.assertNotIn("authorization", request["header_names"])
        self.assertEqual(request["headers"]["X-Volcast-Filename"], "scan.mha")

    def test_a_name_outside_ascii_goes_in_the_query(self):
        # Header values are Latin-1 on the wire: a UTF-8 name travels percent-encoded instead.
        path, _ = self.file_of("kopf_größe.nrrd", 10)
        with RecordingServer() as server:
            run(vc.Client(FakeSocket([]), url=server.url).upload(path))
            (request,) = server.requests
        self.assertEqual(request["target"], "/api/volumes?filename=kopf_gr%C3%B6%C3%9Fe.nrrd")
        self.assertNotIn("x-volcast-filename", request["header_names"])

    def test_the_file_is_read_a_chunk_at_a_time(self):
        class Reader:
            """A 5 MiB file that records how much each read asked for."""
            def __init__(self):
                self.left, self.asked = 5 << 20, []

            def read(self, n=-1):
                self.asked.append(n)
                take = self.left if n < 0 else min(n, self.left)
                self.left -= take
                return bytes(take)

        reader = Reader()
        with RecordingServer() as server:
            answer = vc.post_volume(server.url, reader, 5 << 20, "big.nrrd")
            (request,) = server.requests
        self.assertEqual(answer["volume"], VOLUME)
        self.assertEqual(request["body_bytes"], 5 << 20)
        self.assertTrue(all(0 < n <= vc.upload.CHUNK_BYTES for n in reader.asked),
                        f"reads of {reader.asked}: the whole file was asked for at once")

    def test_a_refusal_raises_upload_error_with_status_and_the_servers_line(self):
        path, _ = self.file_of("junk.nrrd", 100)
        for status, body, message in [
            (422, b"junk.nrrd: NRRD header's sizes hold 'x', which is not a whole number\n",
             "junk.nrrd: NRRD header's sizes hold 'x', which is not a whole number"),
            (415, b"unsupported extension .exe (known: .nrrd, .nii, .nii.gz, .mha, .zip)\nsecond line\n",
             "unsupported extension .exe (known: .nrrd, .nii, .nii.gz, .mha, .zip)"),
            (401, b'{"error": "upload needs the server\'s token"}', "upload needs the server's token"),
            (507, b"", "(no message)"),
        ]:
            with self.subTest(status=status), RecordingServer(answer=(status, "text/plain", body)) as server:
                with self.assertRaises(vc.UploadError) as caught:
                    run(vc.Client(FakeSocket([]), url=server.url).upload(path))
                self.assertEqual((caught.exception.status, caught.exception.message), (status, message))
                self.assertIn(f"upload of 'junk.nrrd': HTTP {status}: {message}", str(caught.exception))

    def test_a_refusal_before_the_body_is_read_still_gives_its_status(self):
        # 64 MiB is more than loopback's socket buffers hold: the client is still sending when
        # the server answers 413 and closes, as a server refusing a Content-Length does.
        body = b"request body of 64 MiB is over the limit of 1 MiB (server flag --max-upload-mib)\n"
        chunk = memoryview(bytes(1 << 20))
        with RecordingServer(answer=(413, "text/plain", body), read_body=False) as server:
            with self.assertRaises(vc.UploadError) as caught:
                vc.post_volume(server.url, (chunk for _ in range(64)), 64 << 20, "big.nrrd", timeout=20)
        error = caught.exception
        # Where the kernel drops the answer with the reset connection, there is no status to
        # give, but the error still says the server closed on the upload.
        if error.status is None:
            self.assertIn("the server closed the connection after", error.message)
        else:
            self.assertEqual((error.status, error.message), (413, body.decode().strip()))

    def test_an_answer_without_a_volume_name_is_an_error(self):
        path, _ = self.file_of("a.nrrd", 10)
        with RecordingServer(answer=(201, "application/json", b'{"id": "x"}')) as server:
            with self.assertRaisesRegex(vc.UploadError, "HTTP 201: the answer is not a JSON object with a volume name"):
                run(vc.Client(FakeSocket([]), url=server.url).upload(path))

    def test_no_server_listening_is_an_upload_error(self):
        with socket.socket() as s:   # a port nobody listens on: bound, never listening
            s.bind(("127.0.0.1", 0))
            url = f"ws://127.0.0.1:{s.getsockname()[1]}/ws"
            with self.assertRaisesRegex(vc.UploadError, r"cannot reach http://127.0.0.1:\d+"):
                vc.post_volume(url, [b"x"], 1, "a.nrrd", timeout=5)

    def test_a_client_without_a_url_says_so(self):
        with self.assertRaisesRegex(ValueError, "no server URL"):
            run(vc.Client(FakeSocket([])).upload(__file__))

    def test_http_endpoint_of_websocket_urls(self):
        self.assertEqual(vc.http_endpoint("ws://127.0.0.1:8080/ws"), ("http", "127.0.0.1", 8080))
        self.assertEqual(vc.http_endpoint("wss://volcast.example.org/ws"), ("https", "volcast.example.org", 443))
        self.assertEqual(vc.http_endpoint("ws://example.org/ws"), ("http", "example.org", 80))
        self.assertEqual(vc.http_endpoint("ws://[::1]:9000/ws"), ("http", "::1", 9000))
        with self.assertRaisesRegex(ValueError, "is not a ws://"):
            vc.http_endpoint("ftp://example.org/")


@unittest.skipIf(np is None, "numpy is not installed (Debian: python3-numpy, in deploy/install.sh)")
class OpenArrayTests(unittest.TestCase):
    def test_open_array_uploads_the_nrrd_then_opens_the_name_it_got(self):
        array = np.arange(2 * 3 * 4, dtype=np.uint16).reshape(2, 3, 4)
        expected = vc.nrrd_bytes(array, spacing=(0.5, 0.5, 2), origin=(1, 2, 3))
        state = {"type": "state", "id": 1, "volume": {"name": VOLUME}, "scene": {},
                 "quality_policy": {"mode": "automatic"}, "interacting": False}

        async def scenario(server):
            socket = FakeSocket([json.dumps(state)])
            client = vc.Client(socket, url=server.url, token="t")
            got = await client.open_array(array, spacing=(0.5, 0.5, 2), origin=(1, 2, 3), name="phantom")
            return got, socket.sent

        with RecordingServer() as server:
            got, sent = run(scenario(server))
            (request,) = server.requests
        self.assertEqual(got, state)
        self.assertEqual(sent, [{"type": "open_volume", "id": 1, "name": VOLUME}])
        self.assertEqual(request["headers"]["X-Volcast-Filename"], "phantom.nrrd")
        self.assertEqual(request["headers"]["Authorization"], "Bearer t")
        self.assertEqual(request["headers"]["Content-Length"], str(len(expected)))
        self.assertEqual(request["body_start"], expected)

    def test_a_refused_array_sends_nothing(self):
        async def scenario(server):
            socket = FakeSocket([])
            with self.assertRaisesRegex(ValueError, "must be 3-D"):
                await vc.Client(socket, url=server.url).open_array(np.zeros((4, 4), np.uint8))
            return socket.sent

        with RecordingServer() as server:
            self.assertEqual(run(scenario(server)), [])
            self.assertEqual(server.requests, [])


if __name__ == "__main__":
    unittest.main()
