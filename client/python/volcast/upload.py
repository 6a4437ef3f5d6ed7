"""Uploads: `POST /api/volumes` on the server's HTTP port (the WebSocket URL's host and port),
the file streamed as the body. Standard library only (http.client); blocking, so Client runs
it in a thread."""

from __future__ import annotations

import http.client
import json
import os
import ssl
import urllib.parse
from typing import Any, BinaryIO, Callable, Dict, Iterable, Optional, Tuple, Union

UPLOAD_PATH = "/api/volumes"
CHUNK_BYTES = 1 << 20          # one socket write; also how often on_progress is called
MAX_ANSWER_BYTES = 64 * 1024   # the server's answers are one JSON object or one line of text
MAX_MESSAGE_CHARS = 500        # of an error's text, in UploadError

Progress = Callable[[int, int], None]


class UploadError(Exception):
    """The server refused an upload (`status` is its HTTP status, `message` its one-line
    reason), or the upload did not reach it (`status` None, `message` says what happened)."""

    def __init__(self, status: Optional[int], message: str, filename: str = "") -> None:
        self.status = status
        self.message = message
        self.filename = filename
        what = f"upload of {filename!r}" if filename else "upload"
        super().__init__(f"{what}: HTTP {status}: {message}" if status is not None else f"{what}: {message}")


def http_endpoint(url: str) -> Tuple[str, str, int]:
    """(scheme, host, port) of the HTTP server behind a WebSocket URL: ws -> http, wss -> https."""
    parts = urllib.parse.urlsplit(url)
    schemes = {"ws": "http", "wss": "https", "http": "http", "https": "https"}
    scheme = schemes.get(parts.scheme.lower())
    if scheme is None or not parts.hostname:
        raise ValueError(f"upload: {url!r} is not a ws://, wss://, http:// or https:// URL with a host")
    port = parts.port or (443 if scheme == "https" else 80)
    return scheme, parts.hostname, port


def _one_line(body: bytes) -> str:
    text = body.decode("utf-8", errors="replace").strip()
    try:
        answer = json.loads(text)
        if isinstance(answer, dict):
            for key in ("message", "error"):
                if isinstance(answer.get(key), str):
                    text = answer[key]
                    break
    except ValueError:
        pass
    line = text.splitlines()[0] if text else "(no message)"
    return line if len(line) <= MAX_MESSAGE_CHARS else line[:MAX_MESSAGE_CHARS] + "…"


def _target_and_name_header(filename: str) -> Tuple[str, Optional[str]]:
    # HTTP header values are Latin-1 on the wire; a name outside printable ASCII goes in the
    # query instead, percent-encoded UTF-8.
    if filename.isascii() and filename.isprintable():
        return UPLOAD_PATH, filename
    return UPLOAD_PATH + "?filename=" + urllib.parse.quote(filename, safe=""), None


def post_volume(url: str, body: Union[BinaryIO, Iterable[Union[bytes, memoryview]]], length: int,
                filename: str, token: Optional[str] = None, timeout: Optional[float] = 600,
                on_progress: Optional[Progress] = None,
                ssl_context: Optional[ssl.SSLContext] = None) -> Dict[str, Any]:
    """POST body (a binary file, read CHUNK_BYTES at a time, or an iterable of byte chunks;
    `length` bytes in all) to the server behind url as a volume named filename. Returns the
    server's 201 answer (`{"volume": "upload:…", "filename", "bytes", "expires_in_s"}`);
    raises UploadError otherwise. timeout: seconds any one connect, write or read may wait
    (the server parses the whole file before it answers). on_progress(sent, length) follows
    each chunk, from the calling thread."""
    if not filename:
        raise ValueError("upload: the file name is empty (the server needs it for the format)")
    scheme, host, port = http_endpoint(url)
    if scheme == "https":
        conn: http.client.HTTPConnection = http.client.HTTPSConnection(
            host, port, timeout=timeout, context=ssl_context or ssl.create_default_context())
    else:
        conn = http.client.HTTPConnection(host, port, timeout=timeout)
    target, name_header = _target_and_name_header(filename)
    if hasattr(body, "read"):
        reader = body
        chunks: Iterable[Union[bytes, memoryview]] = iter(lambda: reader.read(CHUNK_BYTES), b"")  # type: ignore[union-attr]
    else:
        chunks = body  # type: ignore[assignment]
    sent = 0
    try:
        try:
            conn.putrequest("POST", target, skip_accept_encoding=True)
            conn.putheader("Content-Type", "application/octet-stream")
            conn.putheader("Content-Length", str(length))
            if name_header is not None:
                conn.putheader("X-Volcast-Filename", name_header)
            if token:
                conn.putheader("Authorization", f"Bearer {token}")
            conn.endheaders()
        except OSError as e:
            raise UploadError(None, f"cannot reach {scheme}://{host}:{port}: {e}", filename) from None
        refused_while_sending: Optional[OSError] = None
        try:
            for chunk in chunks:
                # Slices of a large buffer, so that progress and timeouts see each piece.
                view = memoryview(chunk).cast("B")
                for start in range(0, len(view), CHUNK_BYTES):
                    piece = view[start:start + CHUNK_BYTES]
                    if sent + len(piece) > length:
                        raise ValueError(f"upload: the body is longer than the {length} bytes announced "
                                         "(did the file grow while it was sent?)")
                    conn.send(piece)
                    sent += len(piece)
                    if on_progress:
                        on_progress(sent, length)
        except (BrokenPipeError, ConnectionResetError) as e:
            # A server refusing early (413 over the size limit, 401) answers and closes before
            # reading the body: its answer may still be there to read.
            refused_while_sending = e
        if refused_while_sending is None and sent != length:
            raise ValueError(f"upload: the body ended after {sent} of the {length} bytes announced "
                             "(did the file shrink while it was sent?)")
        try:
            response = conn.getresponse()
            answer = response.read(MAX_ANSWER_BYTES)
        except (OSError, http.client.HTTPException) as e:
            if refused_while_sending is not None:
                raise UploadError(None, f"the server closed the connection after {sent} of {length} bytes "
                                        f"({refused_while_sending}) without an answer", filename) from None
            raise UploadError(None, f"no answer from {scheme}://{host}:{port}: {e}", filename) from None
    finally:
        conn.close()
    if not 200 <= response.status < 300:
        raise UploadError(response.status, _one_line(answer), filename)
    try:
        result = json.loads(answer)
    except ValueError:
        result = None
    if not isinstance(result, dict) or not isinstance(result.get("volume"), str):
        raise UploadError(response.status, f"the answer is not a JSON object with a volume name: "
                                           f"{_one_line(answer)}", filename)
    return result


def post_file(url: str, path: Union[str, os.PathLike], token: Optional[str] = None,
              filename: Optional[str] = None, timeout: Optional[float] = 600,
              on_progress: Optional[Progress] = None) -> Dict[str, Any]:
    """post_volume of the file at path, streamed from disk, named by its base name unless
    filename is given (the server picks the format from its extension)."""
    name = filename if filename is not None else os.path.basename(os.fspath(path))
    with open(path, "rb") as f:
        length = os.fstat(f.fileno()).st_size
        return post_volume(url, f, length, name, token=token, timeout=timeout, on_progress=on_progress)
