"""One WebSocket session with a volcast server (protocol/README.md). Only Client.connect needs
a WebSocket library: Debian's python3-websockets (10.4), imported when called."""

from __future__ import annotations

import asyncio
import collections
from typing import Any, Callable, Deque, Dict, List, Optional, Protocol, Union

from .frames import Frame, decode_frame
from .messages import RequestId, ServerError, close, dumps, hello, parse_server_message
from .slices import Slice, decode_slice, is_slice_message, slice_request

Message = Dict[str, Any]


class Socket(Protocol):
    """What Client needs of a socket: websockets' client protocol has these."""

    async def send(self, message: str) -> None: ...

    async def recv(self) -> Union[str, bytes]: ...

    async def close(self) -> None: ...


class Client:
    """One session. Anything with async send(str) / recv() -> str | bytes / close() serves as
    the socket (tests pass a stand-in); connect() opens a real WebSocket."""

    def __init__(self, socket: Socket) -> None:
        self._socket = socket
        self._next_id = 1
        # Messages read while waiting for another.
        self._backlog: Deque[Union[Message, Frame, Slice]] = collections.deque()
        self.server_hello: Optional[Message] = None

    @classmethod
    async def connect(cls, url: str, token: Optional[str] = None,
                      client_name: str = "volcast (Python)",
                      max_size: int = 256 * 1024 * 1024) -> Client:
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

    async def __aenter__(self) -> Client:
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self.close()

    async def close(self) -> None:
        """Say close and shut the socket."""
        try:
            await self._socket.send(dumps(close()))
        except Exception:
            pass  # the server may have closed first (after unauthorized, say): nothing to say
        finally:
            await self._socket.close()

    async def send(self, message: Message) -> RequestId:
        """Send a request; gives it the next integer id unless it has one. Returns the id."""
        if "id" not in message:
            message = dict(message, id=self._next_id)
            self._next_id += 1
        await self._socket.send(dumps(message))
        return message["id"]

    async def receive(self, timeout: Optional[float] = None) -> Union[Message, Frame, Slice, None]:
        """The next message: a Frame or a Slice for binary messages, else a dict (errors included).
        None when timeout (s) passes first."""
        if self._backlog:
            return self._backlog.popleft()
        try:
            # Cancelling websockets' recv() is safe: no message is lost.
            raw = await asyncio.wait_for(self._socket.recv(), timeout)
        except asyncio.TimeoutError:
            return None
        if isinstance(raw, (bytes, bytearray)):
            return decode_slice(raw) if is_slice_message(raw) else decode_frame(raw)
        return parse_server_message(raw)

    async def request(self, message: Message, on_progress: Optional[Callable[[Message], None]] = None,
                      timeout: Optional[float] = None) -> Message:
        """Send a request that has a text answer (hello, list_volumes, open_volume, get_state)
        and return that answer; raises ServerError for an error answering it. Progress
        messages for it go to on_progress; anything else read meanwhile is kept for receive()."""
        id = await self.send(message)
        kept: List[Union[Message, Frame, Slice]] = []
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
            elif isinstance(item, dict) and item.get("type") == "error" and (request is None or item.get("id") == request):
                raise ServerError(item)

    async def request_slice(self, axis: str, width: int, height: int, timeout: Optional[float] = None,
                            **fields: Any) -> Slice:
        """Ask for one slice (slice_request's fields: point, center, pixel_spacing, window,
        level) and return the answer with its geometry; raises ServerError for an error
        answering it. Anything else read meanwhile is kept for receive()."""
        id = await self.send(slice_request(axis, width, height, **fields))
        kept: List[Union[Message, Frame, Slice]] = []
        try:
            while True:
                item = await self._read(timeout)
                if isinstance(item, Slice) and item.request == id:
                    return item
                if isinstance(item, dict) and item.get("type") == "error" and item.get("id") == id:
                    raise ServerError(item)
                kept.append(item)
        finally:
            self._backlog.extend(kept)

    async def slice(self, axis: str, width: int, height: int, timeout: Optional[float] = None,
                    **fields: Any) -> "Any":
        """request_slice's pixels as a height x width uint8 numpy array (needs numpy)."""
        return (await self.request_slice(axis, width, height, timeout=timeout, **fields)).to_numpy()

    async def _read(self, timeout: Optional[float]) -> Union[Message, Frame, Slice]:
        item = await self.receive(timeout)
        if item is None:
            raise asyncio.TimeoutError(f"no message from the server in {timeout} s")
        return item
