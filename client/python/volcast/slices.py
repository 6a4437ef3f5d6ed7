"""The `slice` request and its answer, the slice message (protocol/README.md, "slice" and
"Slice messages"): magic b"VCS1", uint32 little-endian header length, a JSON header, then
width x height bytes of 8-bit grey, row 0 at the top.

Standard library only, except Slice.to_numpy, which imports numpy when called."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Dict, Optional, Sequence, Tuple, Union

from .frames import FrameError, _decode_binary, _encode_binary, _import_optional
from .messages import RequestId, _message

if TYPE_CHECKING:
    import numpy

SLICE_MAGIC = b"VCS1"
SLICE_AXES = ("axial", "coronal", "sagittal")
MAX_SLICE_SIDE = 16384


def slice_request(axis: str, width: int, height: int, point: Optional[Sequence[float]] = None,
                  center: Optional[Sequence[float]] = None, pixel_spacing: Optional[float] = None,
                  window: Optional[float] = None, level: Optional[float] = None,
                  id: RequestId = None, slab: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """A `slice` request. point/center are world (patient) mm; window/level data units;
    slab (from slab()) makes it a thick slab."""
    if axis not in SLICE_AXES:
        raise ValueError(f"slice: axis must be one of {SLICE_AXES}, got {axis!r}")
    return _message("slice", id, axis=axis, width=width, height=height,
                    point=list(point) if point is not None else None,
                    center=list(center) if center is not None else None,
                    pixel_spacing=pixel_spacing, window=window, level=level, slab=slab)


SLAB_MODES = ("mip", "minip", "mean")


def slab(thickness: float, mode: str = "mip") -> Dict[str, Any]:
    """A slice's `slab`: planes across [-thickness/2, +thickness/2] mm along its normal,
    combined by their maximum ("mip"), minimum ("minip") or mean; 0 is the plane itself."""
    t = float(thickness)
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"slab: thickness must be a finite number >= 0 mm, got {thickness!r}")
    if mode not in SLAB_MODES:
        raise ValueError(f"slab: mode must be one of {SLAB_MODES}, got {mode!r}")
    return {"thickness": t, "mode": mode}


@dataclass
class Slice:
    """One decoded slice message: its JSON header (keys as on the wire) and grey pixels."""

    header: Dict[str, Any]
    pixels: bytes

    @property
    def request(self) -> Union[int, str, None]:
        return self.header.get("request")

    @property
    def width(self) -> int:
        return self.header["width"]

    @property
    def slab(self) -> Optional[Dict[str, Any]]:
        """The request's slab with its number of planes, or None for a plain slice."""
        return self.header.get("slab")

    @property
    def height(self) -> int:
        return self.header["height"]

    def world_at(self, column: float, row: float) -> Tuple[float, float, float]:
        """The world (patient) point shown at pixel (column, row)'s centre."""
        s = self.header["pixel_spacing"]
        o, c, r = self.header["origin"], self.header["column"], self.header["row"]
        return tuple(o[i] + column * s * c[i] + row * s * r[i] for i in range(3))  # type: ignore[return-value]

    def to_numpy(self) -> "numpy.ndarray":
        """The pixels as a height x width uint8 array. Needs numpy (Debian: python3-numpy)."""
        np = _import_optional("numpy", "python3-numpy", "numpy", "Slice.to_numpy")
        return np.frombuffer(self.pixels, dtype=np.uint8).reshape(self.height, self.width).copy()


def is_slice_message(data: Union[bytes, bytearray, memoryview]) -> bool:
    return bytes(data[:4]) == SLICE_MAGIC


def encode_slice(header: Dict[str, Any], pixels: bytes) -> bytes:
    """The slice message for a header dict and pixels; image_bytes is filled in."""
    return _encode_binary(SLICE_MAGIC, "slice", header, pixels)


def _number(header: Dict[str, Any], key: str) -> float:
    value = header.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise FrameError(f"slice header: {key}: must be a finite number, got {value!r}")
    return value


def decode_slice(data: Union[bytes, bytearray, memoryview]) -> Slice:
    """Decode one slice message; raises FrameError naming what is wrong."""
    header, pixels = _decode_binary(data, SLICE_MAGIC, "slice")
    for key in ("width", "height"):
        value = header.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_SLICE_SIDE:
            raise FrameError(f"slice header: {key}: must be an integer in [1, {MAX_SLICE_SIDE}], got {value!r}")
    if header.get("format") != "gray8":
        raise FrameError(f"slice header: format: unknown pixel format {header.get('format')!r}")
    for key in ("pixel_spacing", "window", "level", "render_ms"):
        _number(header, key)
    for key in ("origin", "column", "row", "point"):
        value = header.get(key)
        if not isinstance(value, list) or len(value) != 3:
            raise FrameError(f"slice header: {key}: must be 3 numbers, got {value!r}")
        for i in range(3):
            _number({f"{key}[{i}]": value[i]}, f"{key}[{i}]")
    expected = header["width"] * header["height"]
    if header.get("image_bytes") != expected or len(pixels) != expected:
        raise FrameError(f"slice: {len(pixels)} pixel bytes (header says {header.get('image_bytes')!r}) "
                         f"for {header['width']} x {header['height']} gray8 pixels")
    return Slice(header, pixels)
