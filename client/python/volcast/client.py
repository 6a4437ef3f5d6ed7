"""One WebSocket session with a volcast server (protocol/README.md). Only Client.connect needs
a WebSocket library: Debian's python3-websockets (10.4), imported when called."""

from __future__ import annotations

import asyncio
import collections
import os
from typing import Any, Callable, Deque, Dict, List, Optional, Protocol, Sequence, Union

from .frames import Frame, decode_frame
from .messages import (MessageError, RequestId, ServerError, StudyDate, close, dumps, find_studies, hello,
                       open_volume, parse_server_message, pick, probe, roi_stats)
from .nrrd import encode_nrrd
from .slices import Slice, decode_slice, is_slice_message, slice_request
from .studies import Study, parse_studies
from .upload import Progress, post_file, post_volume

Message = Dict[str, Any]


class Socket(Protocol):
    """What Client needs of a socket: websockets' client protocol has these."""

    async def send(self, message: str) -> None: ...

    async def recv(self) -> Union[str, bytes]: ...

    async def close(self) -> None: ...


class Client:
    """One session. Anything with async send(str) / recv() -> str | bytes / close() serves as
    the socket (tests pass a stand-in); connect() opens a real WebSocket."""

    def __init__(self, socket: Socket, url: Optional[str] = None, token: Optional[str] = None) -> None:
        self._socket = socket
        # Uploads go to the same host and port over HTTP, with the same token.
        self.url = url
        self.token = token
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
        client = cls(socket, url=url, token=token)
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

    async def open_volume(self, name: str, on_progress: Optional[Callable[[Message], None]] = None,
                          timeout: Optional[float] = None) -> Message:
        """Open a volume (a data-folder name, `builtin:…`, `dicomweb:SOURCE/STUDY/SERIES` or
        `upload:<id>`) and return the server's `state`; raises ServerError when it refuses.
        Its progress messages go to on_progress: `loading` and `preprocessing` with a
        `fraction`, and for a DICOMweb series first `retrieving` with `instances` [done,
        total] and `bytes` where the server knows them."""
        return await self.request(open_volume(name), on_progress=on_progress, timeout=timeout)

    async def find_studies(self, source: str, patient_name: Optional[str] = None,
                           patient_id: Optional[str] = None, study_date: Optional[StudyDate] = None,
                           modality: Optional[str] = None, accession_number: Optional[str] = None,
                           limit: int = 100, timeout: Optional[float] = None) -> List[Study]:
        """Search the server's DICOMweb source `source` for studies (the message builder
        find_studies says what each filter takes); each Study lists its series, whose
        `volume` open_volume takes. Raises ServerError when the server refuses (`not_found`:
        no such source; `source_failed`: the PACS refused or is down; `bad_field`)."""
        answer = await self.request(find_studies(source, patient_name=patient_name, patient_id=patient_id,
                                                 study_date=study_date, modality=modality,
                                                 accession_number=accession_number, limit=limit),
                                    timeout=timeout)
        if answer.get("type") != "studies":
            raise MessageError(f"find_studies: the server answered {answer.get('type')!r}, not studies")
        return parse_studies(answer)

    async def upload(self, path: Union[str, "os.PathLike[str]"], filename: Optional[str] = None,
                     on_progress: Optional[Progress] = None, timeout: Optional[float] = 600) -> str:
        """Upload a volume file (`.nrrd` with attached data, `.nii`, `.nii.gz`, `.mha`, or a
        `.zip` of a DICOM series) with HTTP `POST /api/volumes` to this session's server, and
        return its name (`upload:<id>`) for open_volume. The file is streamed from disk, not
        read whole; the server names it by filename (default: path's base name, whose
        extension gives the format). on_progress(sent, total) follows each MiB sent. Raises
        volcast.UploadError with the HTTP status and the server's reason when it refuses."""
        url = self._upload_url()
        loop = asyncio.get_running_loop()
        answer = await asyncio.to_thread(post_file, url, path, token=self.token, filename=filename,
                                         timeout=timeout, on_progress=self._in_loop(loop, on_progress))
        return answer["volume"]

    async def open_array(self, array: Any, spacing: Sequence[float] = (1, 1, 1),
                         origin: Sequence[float] = (0, 0, 0),
                         direction: Optional[Sequence[Sequence[float]]] = None, name: str = "array.nrrd",
                         on_progress: Optional[Callable[[Message], None]] = None,
                         timeout: Optional[float] = 600) -> Message:
        """Render a numpy volume: upload it as an in-memory NRRD, open it, and return the
        server's `state` (as open_volume). The array is indexed **[z, y, x]**, as numpy
        volumes usually are (SimpleITK's GetArrayFromImage, nibabel's data transposed): its
        last axis is x, the one that varies fastest. spacing and origin are in x, y, z order
        (world units, millimetres for scans), and direction's columns are the unit
        directions of the x, y, z axes in patient space (LPS; 3 rows of 3 numbers, default
        the identity), so voxel array[k, j, i] lies at origin + direction · (i·sx, j·sy,
        k·sz), as the state's `volume` reports it. Types: int8, uint8, int16, uint16, int32,
        uint32, float32, float64; other dtypes (bool, complex, int64, object, …) and arrays
        that are not 3-D raise ValueError saying what to do. A non-contiguous or big-endian
        array is copied once; a C-contiguous little-endian one is sent as it is.
        on_progress gets open_volume's progress messages; timeout bounds the upload's socket
        operations and the wait for the state."""
        header, voxels = encode_nrrd(array, spacing=spacing, origin=origin, direction=direction)
        if not name.lower().endswith(".nrrd"):
            name += ".nrrd"
        url = self._upload_url()
        answer = await asyncio.to_thread(post_volume, url, [header, voxels], len(header) + voxels.nbytes, name,
                                         token=self.token, timeout=timeout)
        return await self.open_volume(answer["volume"], on_progress=on_progress, timeout=timeout)

    def _upload_url(self) -> str:
        if not self.url:
            raise ValueError("upload: this Client has no server URL (Client.connect sets it; "
                             "Client(socket, url=...) otherwise)")
        return self.url

    @staticmethod
    def _in_loop(loop: asyncio.AbstractEventLoop, callback: Optional[Progress]) -> Optional[Progress]:
        # The upload runs in a worker thread; the caller's callback runs in its event loop.
        if callback is None:
            return None
        return lambda sent, total: loop.call_soon_threadsafe(callback, sent, total)

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

    async def probe(self, point: Sequence[float], timeout: Optional[float] = None) -> Message:
        """The `probe` answer for a world point: {"inside", "value", "unit", ...}; value None
        outside the volume, unit "HU" for a CT in Hounsfield units, else None."""
        return await self.request(probe(point), timeout=timeout)

    async def roi_stats(self, axis: str, center: Sequence[float], radii: Sequence[float],
                        shape: str = "ellipse", timeout: Optional[float] = None) -> Message:
        """The `roi_stats` answer: samples, area_mm2, mean, std, min, max (None without samples), unit."""
        return await self.request(roi_stats(axis, center, radii, shape), timeout=timeout)

    async def pick(self, x: float, y: float, width: int, height: int, timeout: Optional[float] = None) -> Message:
        """The `pick` answer for pixel position (x, y) of a width x height image of the view:
        hit, point (world mm, None without a hit) and the ray's opacity."""
        return await self.request(pick(x, y, width, height), timeout=timeout)

    async def _read(self, timeout: Optional[float]) -> Union[Message, Frame, Slice]:
        item = await self.receive(timeout)
        if item is None:
            raise asyncio.TimeoutError(f"no message from the server in {timeout} s")
        return item
