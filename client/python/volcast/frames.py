"""The binary frame message of protocol/README.md: decoding, encoding, and pixels as numpy.

Standard library only, except Frame.to_numpy, which imports numpy and Pillow when called."""

from __future__ import annotations

import io
import json
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Dict, Optional, Tuple, Type, Union

if TYPE_CHECKING:  # only for the annotation; numpy stays optional at run time
    import numpy

FRAME_MAGIC = b"VCF1"
FRAME_PREAMBLE_BYTES = 8  # magic + uint32 little-endian header length
MAX_FRAME_HEADER_BYTES = 64 * 1024
CODECS = ("jpeg", "png")


class FrameError(ValueError):
    """A binary message that is not a valid frame; the text names the problem."""


class MissingDependencyError(ImportError):
    """An optional package a method needs is not installed; the text names it and its
    Debian package."""


def _import_optional(module: str, debian: str, pip: str, needed_by: str) -> Any:
    try:
        return __import__(module)
    except ImportError:
        raise MissingDependencyError(
            f"{needed_by} needs the Python package {pip!r}, which is not installed "
            f"(Debian: apt-get install {debian}; pip: pip install {pip}, or the package's "
            f"[numpy] extra)", name=module) from None


@dataclass
class Frame:
    """One decoded frame: its JSON header (a dict, keys as on the wire) and image bytes."""

    header: Dict[str, Any]
    image: bytes

    @property
    def seq(self) -> int:
        return self.header["seq"]

    @property
    def request(self) -> Union[int, str, None]:
        return self.header.get("request")

    @property
    def level(self) -> int:
        return self.header["level"]

    @property
    def width(self) -> int:
        return self.header["width"]

    @property
    def height(self) -> int:
        return self.header["height"]

    @property
    def view_width(self) -> int:
        """The width of the view the image fills (the viewport): a level of fewer rays is sent
        smaller (width) and shown scaled up to this. An older server's frames lack it: then the
        image's own."""
        return self.header.get("view_width", self.width)

    @property
    def view_height(self) -> int:
        return self.header.get("view_height", self.height)

    @property
    def codec(self) -> str:
        return self.header["codec"]

    @property
    def final(self) -> bool:
        return self.header["final"]

    @property
    def rest_pass(self) -> int:
        """n >= 1 for the n-th pass of refinement at rest after the final frame; 0 otherwise."""
        return self.header.get("rest_pass", 0)

    @property
    def render_ms(self) -> float:
        return self.header["render_ms"]

    @property
    def encode_ms(self) -> float:
        return self.header["encode_ms"]

    @property
    def error(self) -> Optional[Dict[str, Any]]:
        """{"value", "method"}: the server's error estimate, or None."""
        return self.header.get("error")

    @property
    def quality(self) -> Optional[Dict[str, Any]]:
        return self.header.get("quality")

    @property
    def camera(self) -> Optional[Dict[str, Any]]:
        return self.header.get("camera")

    def to_numpy(self, at_view_size: bool = True) -> "numpy.ndarray":
        """The image as a view_height x view_width x 4 uint8 array (RGBA; a JPEG's alpha is
        255): a frame sent smaller than its view (quality image_scale < 1) is scaled up to it,
        bilinearly, as the web client's canvas shows it. at_view_size=False: the image as
        sent, height x width.

        Needs numpy and Pillow (Debian: python3-numpy python3-pil); raises
        MissingDependencyError (an ImportError) naming the one that is absent, and FrameError
        if the image does not decode or its size is not the header's width x height."""
        np = _import_optional("numpy", "python3-numpy", "numpy", "Frame.to_numpy")
        pil = _import_optional("PIL.Image", "python3-pil", "Pillow",
                               f"Frame.to_numpy (decoding {self.codec})")
        Image = pil.Image  # __import__("PIL.Image") returns the PIL package, Image loaded
        try:
            with Image.open(io.BytesIO(self.image), formats=[self.codec.upper()]) as picture:
                rgba = picture.convert("RGBA")
        except (OSError, ValueError) as e:  # Pillow's UnidentifiedImageError is an OSError
            raise FrameError(f"frame {self.seq}: the {self.codec} image does not decode: {e}") from None
        if rgba.size != (self.width, self.height):
            raise FrameError(f"frame {self.seq}: the image is {rgba.size[0]}x{rgba.size[1]} "
                             f"but the header says {self.width}x{self.height}")
        if at_view_size and rgba.size != (self.view_width, self.view_height):
            # The view's size comes from the server like the image: held to the bound Pillow
            # holds a decoded image to (its decompression-bomb error), not up to 65536².
            limit = Image.MAX_IMAGE_PIXELS
            if limit is not None and self.view_width * self.view_height > 2 * limit:
                raise FrameError(f"frame {self.seq}: a view of {self.view_width}x{self.view_height} is over "
                                 f"the {2 * limit} pixels an image may have here (PIL.Image.MAX_IMAGE_PIXELS x 2)")
            rgba = rgba.resize((self.view_width, self.view_height), Image.BILINEAR)
        return np.asarray(rgba, dtype=np.uint8)


def _compact(obj: Any) -> bytes:
    # Sorted keys and no spaces: the same bytes as the C++ encoder (nlohmann::json::dump).
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False).encode("utf-8")


# Frames (VCF1) and slices (VCS1) share one layout: a 4-byte magic, the JSON header's length
# (uint32 little-endian), the header, then the payload, whose length the header's image_bytes
# gives. `what` ("frame", "slice") starts every error message.

def _encode_binary(magic: bytes, what: str, header: Dict[str, Any], payload: bytes) -> bytes:
    text = _compact(dict(header, image_bytes=len(payload)))
    if len(text) > MAX_FRAME_HEADER_BYTES:
        raise FrameError(f"{what} header: {len(text)} bytes, over the limit of {MAX_FRAME_HEADER_BYTES}")
    return magic + struct.pack("<I", len(text)) + text + bytes(payload)


def _decode_binary(data: Union[bytes, bytearray, memoryview], magic: bytes,
                   what: str) -> Tuple[Dict[str, Any], bytes]:
    """The header (a JSON object, not checked further) and the payload after it."""
    data = bytes(data)
    if len(data) < FRAME_PREAMBLE_BYTES:
        raise FrameError(f"{what}: {len(data)} bytes, shorter than the {FRAME_PREAMBLE_BYTES}-byte "
                         "preamble (magic and header length)")
    if data[:4] != magic:
        raise FrameError(f"{what}: starts with {data[:4]!r}, not the magic {magic!r}")
    (length,) = struct.unpack_from("<I", data, 4)
    rest = len(data) - FRAME_PREAMBLE_BYTES
    if length > MAX_FRAME_HEADER_BYTES:
        raise FrameError(f"{what}: header length {length} is over the limit of {MAX_FRAME_HEADER_BYTES} bytes")
    if length > rest:
        raise FrameError(f"{what}: header length {length} runs past the message's end "
                         f"({rest} bytes follow the preamble); truncated?")
    try:
        header = json.loads(data[FRAME_PREAMBLE_BYTES:FRAME_PREAMBLE_BYTES + length].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise FrameError(f"{what} header: malformed JSON: {e}") from None
    if not isinstance(header, dict):
        raise FrameError(f"{what} header: must be a JSON object, got {type(header).__name__}")
    return header, data[FRAME_PREAMBLE_BYTES + length:]


def encode_frame(header: Dict[str, Any], image: bytes) -> bytes:
    """The frame message for a header dict and image; image_bytes is filled in."""
    return _encode_binary(FRAME_MAGIC, "frame", header, image)


def _require(header: Dict[str, Any], key: str, kinds: Tuple[Type[Any], ...], what: str) -> Any:
    if key not in header:
        raise FrameError(f"frame header: {key}: is required")
    value = header[key]
    # bool is an int in Python; only "final" may be one.
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise FrameError(f"frame header: {key}: must be {what}, got {type(value).__name__}")
    return value


def decode_frame(data: Union[bytes, bytearray, memoryview]) -> Frame:
    """Decode one binary frame message; raises FrameError naming what is wrong."""
    header, image = _decode_binary(data, FRAME_MAGIC, "frame")
    for key, low in (("seq", 0), ("level", 0), ("width", 1), ("height", 1)):
        if _require(header, key, (int,), "an integer") < low:
            raise FrameError(f"frame header: {key}: must be at least {low}, got {header[key]}")
    for key, image_key in (("view_width", "width"), ("view_height", "height")):
        if key in header and (_require(header, key, (int,), "an integer") < header[image_key]
                              or header[key] > 65536):
            raise FrameError(f"frame header: {key}: must be an integer in [{header[image_key]}, 65536], "
                             f"got {header[key]}")
    codec = _require(header, "codec", (str,), "a string")
    if codec not in CODECS:
        raise FrameError(f"frame header: codec: unknown codec {codec!r} (known: jpeg, png)")
    _require(header, "render_ms", (int, float), "a number")
    _require(header, "encode_ms", (int, float), "a number")
    _require(header, "final", (bool,), "true or false")
    if "rest_pass" in header and not 0 <= _require(header, "rest_pass", (int,), "an integer") <= 64:
        raise FrameError(f"frame header: rest_pass: must be an integer in [0, 64], got {header['rest_pass']}")
    image_bytes = _require(header, "image_bytes", (int,), "a non-negative integer")
    if image_bytes < 0:
        raise FrameError(f"frame header: image_bytes: must be a non-negative integer, got {image_bytes}")
    if len(image) != image_bytes:
        raise FrameError(f"frame: the header's image_bytes is {image_bytes} but {len(image)} bytes "
                         "follow the header" + ("; truncated?" if len(image) < image_bytes else ""))
    return Frame(header, image)
