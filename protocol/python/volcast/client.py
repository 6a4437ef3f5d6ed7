"""A small client for volcast's WebSocket protocol (protocol/README.md).

The message building and frame decoding here are plain functions of the standard library,
usable and testable offline. Only Client.connect needs Debian's python3-websockets (10.4),
and imports it when called.

    import asyncio, volcast_client as vc

    async def main():
        async with await vc.Client.connect("ws://127.0.0.1:8080/ws") as client:
            state = await client.request(vc.open_volume("bonsai"))
            last = await client.send(vc.camera(state["scene"]["camera"]))
            frame = await client.wait_for_final_frame(request=last)
            open("bonsai.png", "wb").write(frame.image)

    asyncio.run(main())
"""

from __future__ import annotations

import asyncio
import collections
import json
import struct
from dataclasses import dataclass
from typing import Any, Callable, Optional, Union

PROTOCOL_VERSION = 1
FRAME_MAGIC = b"VCF1"
FRAME_PREAMBLE_BYTES = 8  # magic + uint32 little-endian header length
MAX_FRAME_HEADER_BYTES = 64 * 1024

# The stable error codes of protocol/README.md; a newer server may add more.
ERROR_CODES = (
    "malformed_json", "too_large", "bad_message", "unknown_type", "bad_field",
    "unsupported_version", "unauthorized", "bad_state", "bad_volume_name", "not_found",
    "load_failed", "busy", "render_failed", "internal",
)
CLIENT_TYPES = (
    "hello", "list_volumes", "open_volume", "camera", "interaction_start", "interaction_end",
    "viewport", "transfer_function", "quality_policy", "clip_planes", "still", "get_state",
    "close",
)
SERVER_TYPES = ("hello", "volumes", "progress", "state", "error")

RequestId = Union[int, str, None]


class FrameError(ValueError):
    """A binary message that is not a valid frame; the text names the problem."""


class MessageError(ValueError):
    """A server text message that does not follow the protocol."""


class ServerError(Exception):
    """An `error` message from the server, raised where a request expected its answer."""

    def __init__(self, message: dict):
        self.code = message.get("code")
        self.message = message.get("message")
        self.id = message.get("id")
        self.request_type = message.get("request_type")
        super().__init__(f"{self.code}: {self.message} (request {self.request_type} id {self.id!r})")


# --- Frames -------------------------------------------------------------------------------

@dataclass
class Frame:
    """One decoded frame: its JSON header (a dict, keys as on the wire) and image bytes."""

    header: dict
    image: bytes

    seq = property(lambda self: self.header["seq"])
    request = property(lambda self: self.header.get("request"))
    level = property(lambda self: self.header["level"])
    width = property(lambda self: self.header["width"])
    height = property(lambda self: self.header["height"])
    codec = property(lambda self: self.header["codec"])
    final = property(lambda self: self.header["final"])
    render_ms = property(lambda self: self.header["render_ms"])
    encode_ms = property(lambda self: self.header["encode_ms"])
    error = property(lambda self: self.header.get("error"))  # {"value", "method"} or None
    quality = property(lambda self: self.header.get("quality"))
    camera = property(lambda self: self.header.get("camera"))


def _compact(obj: Any) -> bytes:
    # Sorted keys and no spaces: the same bytes as the C++ encoder (nlohmann::json::dump).
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False).encode("utf-8")


def encode_frame(header: dict, image: bytes) -> bytes:
    """The frame message for a header dict and image; image_bytes is filled in."""
    text = _compact(dict(header, image_bytes=len(image)))
    if len(text) > MAX_FRAME_HEADER_BYTES:
        raise FrameError(f"frame header: {len(text)} bytes, over the limit of {MAX_FRAME_HEADER_BYTES}")
    return FRAME_MAGIC + struct.pack("<I", len(text)) + text + bytes(image)


def _require(header: dict, key: str, kinds, what: str):
    if key not in header:
        raise FrameError(f"frame header: {key}: is required")
    value = header[key]
    # bool is an int in Python; only "final" may be one.
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise FrameError(f"frame header: {key}: must be {what}, got {type(value).__name__}")
    return value


def decode_frame(data: bytes) -> Frame:
    """Decode one binary frame message; raises FrameError naming what is wrong."""
    data = bytes(data)
    if len(data) < FRAME_PREAMBLE_BYTES:
        raise FrameError(f"frame: {len(data)} bytes, shorter than the {FRAME_PREAMBLE_BYTES}-byte "
                         "preamble (magic and header length)")
    if data[:4] != FRAME_MAGIC:
        raise FrameError(f"frame: starts with {data[:4]!r}, not the magic b'VCF1'")
    (length,) = struct.unpack_from("<I", data, 4)
    rest = len(data) - FRAME_PREAMBLE_BYTES
    if length > MAX_FRAME_HEADER_BYTES:
        raise FrameError(f"frame: header length {length} is over the limit of {MAX_FRAME_HEADER_BYTES} bytes")
    if length > rest:
        raise FrameError(f"frame: header length {length} runs past the message's end "
                         f"({rest} bytes follow the preamble); truncated?")
    try:
        header = json.loads(data[FRAME_PREAMBLE_BYTES:FRAME_PREAMBLE_BYTES + length].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise FrameError(f"frame header: malformed JSON: {e}") from None
    if not isinstance(header, dict):
        raise FrameError(f"frame header: must be a JSON object, got {type(header).__name__}")
    for key, low in (("seq", 0), ("level", 0), ("width", 1), ("height", 1)):
        if _require(header, key, (int,), "an integer") < low:
            raise FrameError(f"frame header: {key}: must be at least {low}, got {header[key]}")
    codec = _require(header, "codec", (str,), "a string")
    if codec not in ("jpeg", "png"):
        raise FrameError(f"frame header: codec: unknown codec {codec!r} (known: jpeg, png)")
    _require(header, "render_ms", (int, float), "a number")
    _require(header, "encode_ms", (int, float), "a number")
    _require(header, "final", (bool,), "true or false")
    image_bytes = _require(header, "image_bytes", (int,), "a non-negative integer")
    if image_bytes < 0:
        raise FrameError(f"frame header: image_bytes: must be a non-negative integer, got {image_bytes}")
    image = data[FRAME_PREAMBLE_BYTES + length:]
    if len(image) != image_bytes:
        raise FrameError(f"frame: the header's image_bytes is {image_bytes} but {len(image)} bytes "
                         "follow the header" + ("; truncated?" if len(image) < image_bytes else ""))
    return Frame(header, image)


# --- Messages -----------------------------------------------------------------------------

def _message(type_: str, id: RequestId, **fields) -> dict:
    message = {"type": type_}
    if id is not None:
        message["id"] = id
    message.update({k: v for k, v in fields.items() if v is not None})
    return message


def hello(token: Optional[str] = None, client: Optional[str] = None, id: RequestId = None,
          protocol: int = PROTOCOL_VERSION) -> dict:
    return _message("hello", id, protocol=protocol, token=token, client=client)


def list_volumes(id: RequestId = None) -> dict:
    return _message("list_volumes", id)


def open_volume(name: str, id: RequestId = None) -> dict:
    if not isinstance(name, str):
        raise TypeError("open_volume: name must be a string")
    return _message("open_volume", id, name=name)


def camera(camera: dict, id: RequestId = None) -> dict:
    """camera: docs/design.md's scene-file camera, e.g. {"eye", "target", "up", "projection", "fov_y_deg"}."""
    return _message("camera", id, camera=camera)


def interaction_start(id: RequestId = None) -> dict:
    return _message("interaction_start", id)


def interaction_end(id: RequestId = None) -> dict:
    return _message("interaction_end", id)


def viewport(width: int, height: int, id: RequestId = None) -> dict:
    return _message("viewport", id, image={"width": width, "height": height})


def transfer_function(transfer_function: dict, id: RequestId = None) -> dict:
    """transfer_function: {"points": [[value, r, g, b, a], ...], "opacity_unit"} or {"preset": ...}."""
    return _message("transfer_function", id, transfer_function=transfer_function)


def quality_automatic(target_frame_ms: float = 40, quality: Optional[dict] = None,
                      id: RequestId = None) -> dict:
    """Server-chosen levels; quality, when given, is the final level's switches."""
    return _message("quality_policy", id, mode="automatic", target_frame_ms=target_frame_ms,
                    quality=quality)


def quality_explicit(quality: dict, id: RequestId = None) -> dict:
    """Every frame rendered with exactly these docs/design.md switches."""
    return _message("quality_policy", id, mode="explicit", quality=quality)


def clip_planes(planes: list, id: RequestId = None) -> dict:
    """planes: [{"point": [x, y, z], "normal": [x, y, z]}, ...]; [] removes all."""
    return _message("clip_planes", id, clip_planes=list(planes))


def still(width: Optional[int] = None, height: Optional[int] = None, id: RequestId = None) -> dict:
    """A final frame of the current view now; at the viewport's size unless both are given."""
    if (width is None) != (height is None):
        raise ValueError("still: give both width and height, or neither")
    image = None if width is None else {"width": width, "height": height}
    return _message("still", id, image=image)


def get_state(id: RequestId = None) -> dict:
    return _message("get_state", id)


def close(id: RequestId = None) -> dict:
    return _message("close", id)


def dumps(message: dict) -> str:
    """Compact JSON text of a message, as sent."""
    return json.dumps(message, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def parse_server_message(text: Union[str, bytes]) -> dict:
    """A server text message as a dict; raises MessageError if it is not one."""
    try:
        message = json.loads(text)
    except ValueError as e:
        raise MessageError(f"server message: malformed JSON: {e}") from None
    if not isinstance(message, dict):
        raise MessageError(f"server message: must be a JSON object, got {type(message).__name__}")
    if not isinstance(message.get("type"), str):
        raise MessageError("server message: type: is required and must be a string")
    return message


def orbit_camera(base: dict, angle_deg: float) -> dict:
    """base's camera with its eye turned by angle_deg about the axis through target along up."""
    import math

    eye, target, up = base["eye"], base["target"], base["up"]
    norm = math.sqrt(sum(u * u for u in up))
    k = [u / norm for u in up]
    v = [e - t for e, t in zip(eye, target)]
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    # Rodrigues' rotation: v cos + (k x v) sin + k (k . v)(1 - cos).
    cross = [k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]]
    dot = sum(a * b for a, b in zip(k, v))
    rotated = [v[i] * c + cross[i] * s + k[i] * dot * (1 - c) for i in range(3)]
    return dict(base, eye=[t + r for t, r in zip(target, rotated)])


# --- The connection -----------------------------------------------------------------------

class Client:
    """One session. Anything with async send(str) / recv() -> str | bytes / close() serves as
    the socket (tests pass a stand-in); connect() opens a real WebSocket."""

    def __init__(self, socket):
        self._socket = socket
        self._next_id = 1
        self._backlog = collections.deque()  # messages read while waiting for another
        self.server_hello: Optional[dict] = None

    @classmethod
    async def connect(cls, url: str, token: Optional[str] = None,
                      client_name: str = "volcast_client.py", max_size: int = 256 * 1024 * 1024):
        """Open a WebSocket to url and say hello; raises ServerError if the server refuses."""
        import websockets  # Debian: python3-websockets

        # max_size: a final PNG of a large view is many MiB; the library's default is 1 MiB.
        socket = await websockets.connect(url, max_size=max_size)
        client = cls(socket)
        try:
            client.server_hello = await client.request(hello(token=token, client=client_name))
        except BaseException:
            await socket.close()
            raise
        return client

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        await self.close()

    async def close(self):
        """Say close and shut the socket."""
        try:
            await self._socket.send(dumps(close()))
        except Exception:
            pass  # the server may have closed first (after unauthorized, say): nothing to say
        finally:
            await self._socket.close()

    async def send(self, message: dict) -> RequestId:
        """Send a request; gives it the next integer id unless it has one. Returns the id."""
        if "id" not in message:
            message = dict(message, id=self._next_id)
            self._next_id += 1
        await self._socket.send(dumps(message))
        return message["id"]

    async def receive(self, timeout: Optional[float] = None) -> Union[dict, Frame, None]:
        """The next message: a Frame for binary messages, else a dict (errors included).
        None when timeout (s) passes first."""
        if self._backlog:
            return self._backlog.popleft()
        try:
            # Cancelling websockets' recv() is safe: no message is lost.
            raw = await asyncio.wait_for(self._socket.recv(), timeout)
        except asyncio.TimeoutError:
            return None
        return decode_frame(raw) if isinstance(raw, (bytes, bytearray)) else parse_server_message(raw)

    async def request(self, message: dict, on_progress: Optional[Callable[[dict], None]] = None,
                      timeout: Optional[float] = None) -> dict:
        """Send a request that has a text answer (hello, list_volumes, open_volume, get_state)
        and return that answer; raises ServerError for an error answering it. Progress
        messages for it go to on_progress; anything else read meanwhile is kept for receive()."""
        id = await self.send(message)
        kept = []
        try:
            while True:
                reply = await self._read(timeout)
                if isinstance(reply, dict) and reply.get("id") == id:
                    if reply["type"] == "progress":
                        if on_progress:
                            on_progress(reply)
                        continue
                    if reply["type"] == "error":
                        raise ServerError(reply)
                    return reply
                kept.append(reply)
        finally:
            self._backlog.extend(kept)

    async def wait_for_final_frame(self, request: RequestId = None, timeout: Optional[float] = None,
                                   on_frame: Optional[Callable[[Frame], None]] = None) -> Frame:
        """Read until a final frame (answering request, when given) arrives and return it.
        Earlier frames go to on_frame; an error answering request raises ServerError; other
        text messages are skipped."""
        while True:
            item = await self._read(timeout)
            if isinstance(item, Frame):
                if item.final and (request is None or item.request == request):
                    return item
                if on_frame:
                    on_frame(item)
            elif item.get("type") == "error" and (request is None or item.get("id") == request):
                raise ServerError(item)

    async def _read(self, timeout: Optional[float]):
        item = await self.receive(timeout)
        if item is None:
            raise asyncio.TimeoutError(f"no message from the server in {timeout} s")
        return item
