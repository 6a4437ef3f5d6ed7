"""A raw WebSocket client (RFC 6455) over asyncio streams, for hostile and scripted traffic.

A conforming library refuses to send what the soak must send (invalid UTF-8 as text, broken
fragmentation, unmasked or reserved frames), so this writes the frames itself. Reading
assembles fragmented messages, answers pings and reports the server's close code.
"""

from __future__ import annotations

import asyncio
import base64
import os
import socket
import struct
from typing import Optional

OP_CONTINUATION, OP_TEXT, OP_BINARY, OP_CLOSE, OP_PING, OP_PONG = 0x0, 0x1, 0x2, 0x8, 0x9, 0xA


class ConnectionLost(Exception):
    """The TCP connection ended without a WebSocket close frame from the server."""


class Closed(Exception):
    """The server sent a close frame: `code` (None when the frame had no code) and `reason`."""

    def __init__(self, code: Optional[int], reason: str):
        super().__init__(f"closed by the server: {code} {reason!r}")
        self.code = code
        self.reason = reason


def frame_bytes(opcode: int, payload: bytes, fin: bool = True, mask: bool = True, rsv: int = 0) -> bytes:
    """One WebSocket frame as a client writes it (masked unless told otherwise)."""
    head = bytearray([(0x80 if fin else 0) | (rsv & 0x7) << 4 | (opcode & 0xF)])
    n = len(payload)
    mask_bit = 0x80 if mask else 0
    if n < 126:
        head.append(mask_bit | n)
    elif n < 1 << 16:
        head.append(mask_bit | 126)
        head += struct.pack(">H", n)
    else:
        head.append(mask_bit | 127)
        head += struct.pack(">Q", n)
    if not mask:
        return bytes(head) + payload
    key = os.urandom(4)
    # XOR with the repeated key through one big integer: fast for large payloads.
    repeated = (key * (n // 4 + 1))[:n]
    masked = (int.from_bytes(payload, "little") ^ int.from_bytes(repeated, "little")).to_bytes(n, "little")
    return bytes(head) + key + masked


class RawWebSocket:
    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        self.reader = reader
        self.writer = writer
        self.close_code: Optional[int] = None
        self.close_reason = ""

    @classmethod
    async def connect(cls, host: str, port: int, path: str = "/ws", timeout: float = 10.0,
                      extra_headers: str = "") -> "RawWebSocket":
        reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
        # Without it a small write waits for the server's delayed ACK: 40 ms stalls.
        writer.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        key = base64.b64encode(os.urandom(16)).decode()
        request = (f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                   f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                   f"{extra_headers}\r\n")
        writer.write(request.encode())
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), timeout)
        except (asyncio.IncompleteReadError, ConnectionError) as e:
            writer.close()
            raise ConnectionLost(f"handshake: connection ended ({e})") from None
        status = head.split(b"\r\n", 1)[0]
        if b" 101 " not in status + b" ":
            writer.close()
            raise ConnectionLost(f"handshake refused: {status.decode(errors='replace')}")
        return cls(reader, writer)

    async def send_raw(self, data: bytes) -> None:
        self.writer.write(data)
        await self.writer.drain()

    async def send_text(self, payload: bytes) -> None:
        await self.send_raw(frame_bytes(OP_TEXT, payload))

    async def send_binary(self, payload: bytes) -> None:
        await self.send_raw(frame_bytes(OP_BINARY, payload))

    async def _read_frame(self):
        try:
            b0, b1 = await self.reader.readexactly(2)
            n = b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack(">H", await self.reader.readexactly(2))
            elif n == 127:
                (n,) = struct.unpack(">Q", await self.reader.readexactly(8))
            key = await self.reader.readexactly(4) if b1 & 0x80 else None
            payload = await self.reader.readexactly(n)
        except (asyncio.IncompleteReadError, ConnectionError) as e:
            raise ConnectionLost(f"connection ended mid-read ({type(e).__name__})") from None
        if key is not None:  # servers must not mask; undo it anyway so the error names the real issue
            payload = bytes(c ^ key[i % 4] for i, c in enumerate(payload))
        return bool(b0 & 0x80), b0 & 0x0F, payload

    async def receive(self):
        """The next data message as ("text" | "binary", bytes); raises Closed or ConnectionLost."""
        kind = None
        parts = []
        while True:
            fin, opcode, payload = await self._read_frame()
            if opcode == OP_CLOSE:
                code = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else None
                self.close_code = code
                self.close_reason = payload[2:].decode("utf-8", errors="replace")
                try:  # echo the close, as RFC 6455 asks, then end the connection
                    self.writer.write(frame_bytes(OP_CLOSE, payload[:2]))
                    self.writer.close()
                except (ConnectionError, RuntimeError):
                    pass
                raise Closed(code, self.close_reason)
            if opcode == OP_PING:
                await self.send_raw(frame_bytes(OP_PONG, payload))
                continue
            if opcode == OP_PONG:
                continue
            if opcode in (OP_TEXT, OP_BINARY):
                kind = "text" if opcode == OP_TEXT else "binary"
                parts = [payload]
            else:
                parts.append(payload)
            if fin:
                return kind, b"".join(parts)

    async def close(self, code: int = 1000) -> None:
        try:
            await self.send_raw(frame_bytes(OP_CLOSE, struct.pack(">H", code)))
        except (ConnectionError, RuntimeError):
            pass
        self.abort()

    def abort(self) -> None:
        try:
            self.writer.close()
        except RuntimeError:
            pass
