"""The text messages of protocol/README.md: builders for every client request, parsing of
the server's messages, and the error a server's refusal becomes. Standard library only."""

from __future__ import annotations

import datetime
import json
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

PROTOCOL_VERSION = 1

# The stable error codes of protocol/README.md; a newer server may add more.
ERROR_CODES = (
    "malformed_json", "too_large", "bad_message", "unknown_type", "bad_field",
    "unsupported_version", "unauthorized", "bad_state", "bad_volume_name", "not_found",
    "load_failed", "busy", "render_failed", "internal", "source_failed",
)
CLIENT_TYPES = (
    "hello", "list_volumes", "open_volume", "camera", "interaction_start", "interaction_end",
    "viewport", "transfer_function", "quality_policy", "clip_planes", "still", "get_state",
    "close", "slice", "find_studies", "probe", "roi_stats", "pick",
)
SERVER_TYPES = ("hello", "volumes", "progress", "state", "error", "studies", "probe", "roi_stats", "pick")

RequestId = Union[int, str, None]


class MessageError(ValueError):
    """A server text message that does not follow the protocol."""


class ServerError(Exception):
    """An `error` message from the server, raised where a request expected its answer."""

    def __init__(self, message: Dict[str, Any]) -> None:
        self.code = message.get("code")
        self.message = message.get("message")
        self.id = message.get("id")
        self.request_type = message.get("request_type")
        # load_failed of a series of several stacks: each stack as the server sent it, a dict
        # {"volume": the name that opens it, "slices", "rows", "columns", "orientation", "localizer"}.
        stacks = message.get("stacks")
        self.stacks: List[Dict[str, Any]] = [s for s in stacks if isinstance(s, dict)] if isinstance(stacks, list) else []
        super().__init__(f"{self.code}: {self.message} (request {self.request_type} id {self.id!r})")


def _message(type_: str, id: RequestId, **fields: Any) -> Dict[str, Any]:
    message: Dict[str, Any] = {"type": type_}
    if id is not None:
        message["id"] = id
    message.update({k: v for k, v in fields.items() if v is not None})
    return message


def hello(token: Optional[str] = None, client: Optional[str] = None, id: RequestId = None,
          protocol: int = PROTOCOL_VERSION) -> Dict[str, Any]:
    return _message("hello", id, protocol=protocol, token=token, client=client)


def list_volumes(id: RequestId = None) -> Dict[str, Any]:
    return _message("list_volumes", id)


def open_volume(name: str, id: RequestId = None) -> Dict[str, Any]:
    """name: as `volumes` lists it (`ct/head.nrrd`, `builtin:demo`), a series `find_studies`
    found (`dicomweb:SOURCE/STUDY_UID/SERIES_UID`), or what an upload answered (`upload:<id>`).
    The server checks the name; the client sends it as it is."""
    if not isinstance(name, str):
        raise TypeError("open_volume: name must be a string")
    return _message("open_volume", id, name=name)


DateLike = Union[str, datetime.date]
StudyDate = Union[DateLike, Tuple[Optional[DateLike], Optional[DateLike]]]


def _dicom_date(value: Optional[DateLike], what: str) -> str:
    if value is None:
        return ""
    if isinstance(value, datetime.date):
        return value.strftime("%Y%m%d")
    if isinstance(value, str):
        return value
    raise TypeError(f"find_studies: {what} must be a 'YYYYMMDD' string or a datetime.date, "
                    f"got {type(value).__name__}")


def find_studies(source: str, patient_name: Optional[str] = None, patient_id: Optional[str] = None,
                 study_date: Optional[StudyDate] = None, modality: Optional[str] = None,
                 accession_number: Optional[str] = None, limit: int = 100,
                 id: RequestId = None) -> Dict[str, Any]:
    """Search a DICOMweb source the server names (`volumes`' `sources`) for studies.
    patient_name may hold DICOM wildcards (`*`, `?`); study_date is "YYYYMMDD", a range
    "YYYYMMDD-YYYYMMDD" (either end may be empty), a datetime.date, or a (first, last) pair
    of those (None for an open end). Filters left as None are not sent; limit is 1..1000."""
    if not isinstance(source, str) or not source:
        raise ValueError("find_studies: source must be a non-empty string (a source the server names)")
    if isinstance(limit, bool) or not isinstance(limit, int) or not 1 <= limit <= 1000:
        raise ValueError(f"find_studies: limit must be an integer in 1..1000, got {limit!r}")
    if isinstance(study_date, tuple):
        if len(study_date) != 2:
            raise ValueError("find_studies: a study_date range is a (first, last) pair")
        study_date = (f"{_dicom_date(study_date[0], 'study_date[0]')}-"
                      f"{_dicom_date(study_date[1], 'study_date[1]')}")
    elif study_date is not None:
        study_date = _dicom_date(study_date, "study_date")
    filters = {"patient_name": patient_name, "patient_id": patient_id, "study_date": study_date,
               "modality": modality, "accession_number": accession_number}
    for key, value in filters.items():
        if value is not None and not isinstance(value, str):
            raise TypeError(f"find_studies: {key} must be a string, got {type(value).__name__}")
    return _message("find_studies", id, source=source,
                    filters={k: v for k, v in filters.items() if v is not None}, limit=limit)


def camera(camera: Dict[str, Any], id: RequestId = None) -> Dict[str, Any]:
    """camera: docs/design.md's scene-file camera, e.g. {"eye", "target", "up", "projection", "fov_y_deg"}."""
    return _message("camera", id, camera=camera)


def interaction_start(id: RequestId = None) -> Dict[str, Any]:
    return _message("interaction_start", id)


def interaction_end(id: RequestId = None) -> Dict[str, Any]:
    return _message("interaction_end", id)


def viewport(width: int, height: int, id: RequestId = None) -> Dict[str, Any]:
    return _message("viewport", id, image={"width": width, "height": height})


def transfer_function(transfer_function: Dict[str, Any], id: RequestId = None) -> Dict[str, Any]:
    """transfer_function: {"points": [[value, r, g, b, a], ...], "opacity_unit"} or {"preset": ...}."""
    return _message("transfer_function", id, transfer_function=transfer_function)


def quality_automatic(target_frame_ms: float = 40, quality: Optional[Dict[str, Any]] = None,
                      id: RequestId = None) -> Dict[str, Any]:
    """Server-chosen levels; quality, when given, is the final level's switches."""
    return _message("quality_policy", id, mode="automatic", target_frame_ms=target_frame_ms,
                    quality=quality)


def quality_explicit(quality: Dict[str, Any], id: RequestId = None) -> Dict[str, Any]:
    """Every frame rendered with exactly these docs/design.md switches."""
    return _message("quality_policy", id, mode="explicit", quality=quality)


COMPOSITING_MODES = ("emission_absorption", "mip", "minip")


def crop_box(min: Sequence[float] = (0, 0, 0), max: Sequence[float] = (1, 1, 1)) -> Dict[str, Any]:
    """quality.crop: six axis-aligned faces in the volume's own axes, normalised box
    coordinates (0 and 1 are the outer faces of the outermost voxels), 0 <= min < max <= 1."""
    lo, hi = [float(v) for v in min], [float(v) for v in max]
    if len(lo) != 3 or len(hi) != 3:
        raise ValueError("crop_box: min and max need 3 numbers each")
    for a in range(3):
        if not 0 <= lo[a] < hi[a] <= 1:
            raise ValueError(f"crop_box: axis {a} needs 0 <= min < max <= 1, got {lo[a]}, {hi[a]}")
    return {"min": lo, "max": hi}


def projection_window(window: float, level: float) -> Dict[str, Any]:
    """quality.projection_window: the grey window of a MIP / MinIP in data units; the extreme
    value v along a ray shows as clamp((v - (level - window/2)) / window, 0, 1), opaque."""
    w, l = float(window), float(level)
    if not (math.isfinite(w) and w > 0) or not math.isfinite(l):
        raise ValueError(f"projection_window: window must be finite and > 0 and level finite, got {window!r}, {level!r}")
    return {"window": w, "level": l}


def with_compositing(quality: Optional[Dict[str, Any]] = None, compositing: Optional[str] = None,
                     crop: Optional[Dict[str, Any]] = None,
                     window: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """A copy of the quality switches with quality.compositing ("emission_absorption", "mip"
    or "minip"), quality.crop (from crop_box) and quality.projection_window (from
    projection_window) set, for quality_explicit/_automatic."""
    q = dict(quality or {})
    if compositing is not None:
        if compositing not in COMPOSITING_MODES:
            raise ValueError(f"compositing must be one of {', '.join(COMPOSITING_MODES)}, got {compositing!r}")
        q["compositing"] = compositing
    if crop is not None:
        q["crop"] = crop
    if window is not None:
        q["projection_window"] = window
    return q


def _point(point: Sequence[float], what: str) -> List[float]:
    values = [float(v) for v in point]
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what}: must be 3 finite numbers, got {point!r}")
    return values


def probe(point: Sequence[float], id: RequestId = None) -> Dict[str, Any]:
    """The volume's value at a world (patient) point, mm; answered by a `probe` message."""
    return _message("probe", id, point=_point(point, "probe: point"))


ROI_SHAPES = ("ellipse", "rectangle")


def roi_stats(axis: str, center: Sequence[float], radii: Sequence[float], shape: str = "ellipse",
              id: RequestId = None) -> Dict[str, Any]:
    """Statistics of the values in an ellipse (or rectangle of half sides) on a slice pane's
    plane through center; radii (a, b) in mm along the pane's column and row directions."""
    if axis not in ("axial", "coronal", "sagittal"):
        raise ValueError(f"roi_stats: axis must be axial, coronal or sagittal, got {axis!r}")
    if shape not in ROI_SHAPES:
        raise ValueError(f"roi_stats: shape must be one of {ROI_SHAPES}, got {shape!r}")
    r = [float(v) for v in radii]
    if len(r) != 2 or not all(math.isfinite(v) and v > 0 for v in r):
        raise ValueError(f"roi_stats: radii must be 2 finite numbers > 0, got {radii!r}")
    return _message("roi_stats", id, axis=axis, center=_point(center, "roi_stats: center"), radii=r, shape=shape)


def pick(x: float, y: float, width: int, height: int, id: RequestId = None) -> Dict[str, Any]:
    """Where the ray through pixel position (x, y) (pixel centres at +0.5, origin top-left) of a
    width x height image of the session's view first becomes half opaque."""
    return _message("pick", id, x=float(x), y=float(y), width=int(width), height=int(height))


def clip_planes(planes: List[Dict[str, Any]], id: RequestId = None) -> Dict[str, Any]:
    """planes: [{"point": [x, y, z], "normal": [x, y, z]}, ...]; [] removes all."""
    return _message("clip_planes", id, clip_planes=list(planes))


def still(width: Optional[int] = None, height: Optional[int] = None, id: RequestId = None) -> Dict[str, Any]:
    """A final frame of the current view now; at the viewport's size unless both are given."""
    if (width is None) != (height is None):
        raise ValueError("still: give both width and height, or neither")
    image = None if width is None else {"width": width, "height": height}
    return _message("still", id, image=image)


def get_state(id: RequestId = None) -> Dict[str, Any]:
    return _message("get_state", id)


def close(id: RequestId = None) -> Dict[str, Any]:
    return _message("close", id)


def dumps(message: Dict[str, Any]) -> str:
    """Compact JSON text of a message, as sent."""
    return json.dumps(message, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def parse_server_message(text: Union[str, bytes]) -> Dict[str, Any]:
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


def orbit_camera(base: Dict[str, Any], angle_deg: float) -> Dict[str, Any]:
    """base's camera with its eye turned by angle_deg about the axis through target along up."""
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


def preset(volume: Dict[str, Any], name: Optional[str] = None) -> Dict[str, Any]:
    """The display preset `name` (default: the one the volume opened with) that the server sent
    with a loaded volume object (its `modality`, protocol/README.md): a dict with `points` in
    the volume's data units, `window`, `level` and `shading`. Send it with
    transfer_function({"points": p["points"]}) and the quality switch shading=p["shading"].
    Raises KeyError naming the presets there are."""
    modality = volume.get("modality") or {}
    presets = modality.get("presets") or []
    wanted = name if name is not None else modality.get("default_preset")
    for p in presets:
        if p.get("name") == wanted:
            return p
    known = ", ".join(str(p.get("name")) for p in presets) or "none: the server sent no presets for this volume"
    raise KeyError(f"no preset {wanted!r} for volume {volume.get('name')!r} (known: {known})")
