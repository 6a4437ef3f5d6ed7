"""volcast: a client for volcast's WebSocket protocol (protocol/README.md).

    import asyncio
    import volcast

    async def main() -> None:
        async with await volcast.Client.connect("ws://127.0.0.1:8080/ws") as client:
            state = await client.request(volcast.open_volume("bonsai"))
            last = await client.send(volcast.camera(state["scene"]["camera"]))
            frame = await client.wait_for_final_frame(request=last)
            open("bonsai.png", "wb").write(frame.image)
            pixels = frame.to_numpy()  # height x width x 4 uint8; needs numpy and Pillow

    asyncio.run(main())

A numpy volume (indexed [z, y, x]) is rendered with
`state = await client.open_array(volume, spacing=(sx, sy, sz))`; a file is sent with
`await client.upload(path)`, a PACS searched with `await client.find_studies(source, ...)`.

Message building, frame decoding and uploads are standard library only; only
Client.connect needs websockets, Frame.to_numpy numpy and Pillow, and open_array numpy.
"""

from .client import Client, Socket
from .frames import (CODECS, FRAME_MAGIC, FRAME_PREAMBLE_BYTES, MAX_FRAME_HEADER_BYTES, Frame,
                     FrameError, MissingDependencyError, decode_frame, encode_frame)
from .messages import (CLIENT_TYPES, COMPOSITING_MODES, ERROR_CODES, PROTOCOL_VERSION, SERVER_TYPES, MessageError,
                       RequestId, ServerError, camera, clip_planes, close, dumps, get_state, hello,
                       interaction_end, interaction_start, list_volumes, open_volume, orbit_camera,
                       parse_server_message, preset, quality_automatic, quality_explicit, still,
                       transfer_function, viewport, crop_box, with_compositing, find_studies,
                       projection_window, probe, roi_stats, pick, ROI_SHAPES)
from .nrrd import NRRD_TYPES, encode_nrrd, nrrd_bytes, nrrd_header
from .studies import Series, Study, parse_studies
from .upload import UploadError, http_endpoint, post_file, post_volume
from .slices import (SLAB_MODES, SLICE_AXES, SLICE_MAGIC, Slice, decode_slice, encode_slice, is_slice_message,
                     slab, slice_request)

__version__ = "0.1.0"  # the project's version (CMakeLists.txt) and pyproject.toml's

__all__ = [
    "Client", "Socket",
    "CODECS", "FRAME_MAGIC", "FRAME_PREAMBLE_BYTES", "MAX_FRAME_HEADER_BYTES", "Frame",
    "FrameError", "MissingDependencyError", "decode_frame", "encode_frame",
    "CLIENT_TYPES", "ERROR_CODES", "PROTOCOL_VERSION", "SERVER_TYPES", "MessageError",
    "RequestId", "ServerError", "camera", "clip_planes", "close", "dumps", "get_state", "hello",
    "interaction_end", "interaction_start", "list_volumes", "open_volume", "orbit_camera",
    "parse_server_message", "preset", "quality_automatic", "quality_explicit", "still",
    "transfer_function", "viewport", "COMPOSITING_MODES", "crop_box", "with_compositing",
    "SLICE_AXES", "SLICE_MAGIC", "Slice", "decode_slice", "encode_slice", "is_slice_message",
    "slice_request", "find_studies", "projection_window", "probe", "roi_stats", "pick", "ROI_SHAPES",
    "SLAB_MODES", "slab", "Series", "Study", "parse_studies",
    "NRRD_TYPES", "encode_nrrd", "nrrd_bytes", "nrrd_header",
    "UploadError", "http_endpoint", "post_file", "post_volume",
]
