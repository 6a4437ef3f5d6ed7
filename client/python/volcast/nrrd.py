"""An in-memory NRRD file of a numpy volume, for Client.open_array: a header with the
volume's geometry in patient space (LPS), then the voxels, raw and little-endian. Needs
numpy, imported when called."""

from __future__ import annotations

import math
from typing import Any, Optional, Sequence, Tuple

from .frames import _import_optional

# numpy dtype name -> NRRD type name; the voxel types the server loads (renderer/io).
NRRD_TYPES = {
    "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16",
    "int32": "int32", "uint32": "uint32", "float32": "float", "float64": "double",
}

IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

# A direction column farther than this from unit length is a caller's mistake, not rounding:
# float32 matrices written out with 7 digits land within about 1e-7 of it.
UNIT_TOLERANCE = 1e-5


def _three(values: Sequence[Any], what: str) -> Tuple[float, float, float]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"open_array: {what} must be 3 numbers, got {values!r}") from None
    if len(out) != 3:
        raise ValueError(f"open_array: {what} must be 3 numbers (x, y, z), got {len(out)}")
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"open_array: {what} must be finite, got {out}")
    return out  # type: ignore[return-value]


def _direction(direction: Optional[Sequence[Sequence[Any]]]) -> Tuple[Tuple[float, ...], ...]:
    if direction is None:
        return IDENTITY
    try:
        rows = [list(row) for row in direction]
    except TypeError:
        raise ValueError(f"open_array: direction must be 3 rows of 3 numbers, got {direction!r}") from None
    if len(rows) != 3:
        raise ValueError(f"open_array: direction must be 3 rows of 3 numbers, got {len(rows)} rows")
    d = tuple(_three(row, f"direction row {r}") for r, row in enumerate(rows))
    for c, axis in enumerate("xyz"):
        length = math.sqrt(sum(d[r][c] ** 2 for r in range(3)))
        if abs(length - 1) > UNIT_TOLERANCE:
            raise ValueError(f"open_array: direction column {c} (the {axis} axis) must have unit length, "
                             f"got {length:.6g}; spacing carries the voxel size")
    det = (d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1])
           - d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0])
           + d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]))
    if abs(det) < 1e-6:
        raise ValueError("open_array: direction is singular: its columns (the x, y, z axes) are not independent")
    return d


def _number(v: float) -> str:
    # repr is the shortest text that reads back as the same double.
    return repr(float(v))


def _vector(v: Sequence[float]) -> str:
    return "(" + ",".join(_number(x) for x in v) + ")"


def voxel_array(array: Any) -> Any:
    """array as a C-contiguous, little-endian 3-D numpy array of a type the server loads (a
    copy only where needed); ValueError naming what is wrong otherwise."""
    np = _import_optional("numpy", "python3-numpy", "numpy", "open_array")
    a = np.asarray(array)
    kind = a.dtype.kind
    if kind == "b":
        raise ValueError("open_array: boolean arrays are not supported; send a mask as uint8 "
                         "(array.astype(numpy.uint8))")
    if kind == "c":
        raise ValueError(f"open_array: complex arrays ({a.dtype}) are not supported; send a real "
                         "volume (numpy.abs(array) or array.real)")
    if kind not in "iuf" or a.dtype.name not in NRRD_TYPES:
        raise ValueError(f"open_array: arrays of {a.dtype} are not supported; the server loads "
                         f"{', '.join(NRRD_TYPES)} (cast with array.astype(...))")
    if a.ndim != 3:
        raise ValueError(f"open_array: the array must be 3-D, indexed [z, y, x]; got {a.ndim}-D, "
                         f"shape {a.shape}")
    if 0 in a.shape:
        raise ValueError(f"open_array: every axis needs at least one sample, got shape {a.shape}")
    return np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))


def nrrd_header(shape_zyx: Sequence[int], dtype_name: str, spacing: Sequence[float] = (1, 1, 1),
                origin: Sequence[float] = (0, 0, 0),
                direction: Optional[Sequence[Sequence[float]]] = None) -> bytes:
    """The NRRD header (through its blank line) of a volume of shape [z, y, x] (numpy's order),
    written with sizes x y z. spacing and origin are x, y, z; direction's columns are the x,
    y, z axes' unit directions in patient space (LPS), as the server's `direction`."""
    if dtype_name not in NRRD_TYPES:
        raise ValueError(f"open_array: arrays of {dtype_name} are not supported; the server loads "
                         f"{', '.join(NRRD_TYPES)}")
    nz, ny, nx = (int(n) for n in shape_zyx)
    s = _three(spacing, "spacing")
    if not all(v > 0 for v in s):
        raise ValueError(f"open_array: spacing must be positive, got {s}")
    o = _three(origin, "origin")
    d = _direction(direction)
    # Axis a's step in patient space: column a of the direction, times that axis' spacing.
    steps = [[d[r][a] * s[a] for r in range(3)] for a in range(3)]
    lines = [
        "NRRD0004",
        "# written by the volcast Python client (open_array)",
        f"type: {NRRD_TYPES[dtype_name]}",
        "dimension: 3",
        "space: left-posterior-superior",
        f"sizes: {nx} {ny} {nz}",
        "space directions: " + " ".join(_vector(step) for step in steps),
        "kinds: domain domain domain",
    ]
    if dtype_name not in ("int8", "uint8"):
        lines.append("endian: little")
    lines += ["encoding: raw", f"space origin: {_vector(o)}", "", ""]
    return "\n".join(lines).encode("ascii")


def encode_nrrd(array: Any, spacing: Sequence[float] = (1, 1, 1), origin: Sequence[float] = (0, 0, 0),
                direction: Optional[Sequence[Sequence[float]]] = None) -> Tuple[bytes, memoryview]:
    """(header, voxels) of array as a NRRD file: send the two one after the other. array is
    indexed [z, y, x] (numpy's usual order for volumes: x varies fastest); voxels is a byte
    view of a C-contiguous little-endian copy, or of array itself where it already is one."""
    voxels = voxel_array(array)
    header = nrrd_header(voxels.shape, voxels.dtype.name, spacing, origin, direction)
    return header, memoryview(voxels.reshape(-1).view("uint8"))


def nrrd_bytes(array: Any, spacing: Sequence[float] = (1, 1, 1), origin: Sequence[float] = (0, 0, 0),
               direction: Optional[Sequence[Sequence[float]]] = None) -> bytes:
    """encode_nrrd's header and voxels as one bytes object (a copy: for small volumes)."""
    header, voxels = encode_nrrd(array, spacing, origin, direction)
    return header + voxels.tobytes()
