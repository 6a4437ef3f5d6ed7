"""Hostile messages for the soak: structured-random requests gone wrong, and byte-level
mutations of valid ones. Each generator returns a Hostile: what to send and what answer the
protocol documents for it.

`expect_code` is set where protocol/README.md names exactly one answer (a binary message is
`bad_message`, a duplicate key `bad_field`, ...); `expect_close` where the WebSocket layer
answers with a close instead (RFC 6455: 1007 invalid UTF-8 in a text message, 1009 a
message over the WebSocket limit, 1002 a broken frame). Otherwise any documented answer
passes: an `error` with a documented code other than `internal`, or the normal reply of a
request that happened to be valid.
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass, field
from typing import Callable, List, Optional, Tuple

from rawws import OP_BINARY, OP_CONTINUATION, OP_PING, OP_TEXT, frame_bytes

MAX_MESSAGE_BYTES = 65536           # the server's default --max-message-bytes
WS_LIMIT_BYTES = 16 * MAX_MESSAGE_BYTES   # server/README.md: the WebSocket layer closes above this
MAX_DEPTH = 32                      # protocol/README.md: too_large when nested deeper


@dataclass
class Hostile:
    category: str
    frames: List[bytes]                 # the raw WebSocket frames to write, in order
    payload: bytes                      # the message as the server will see it (for reports)
    binary: bool = False
    expect_code: Optional[str] = None
    expect_close: Tuple[int, ...] = ()
    may_close_normally: bool = False    # a valid `close` request: the server closes with 1000
    needs_answer: bool = True           # False where the message may be a valid request answered by frames only
    may_drop: bool = False              # the connection may end without a close frame (see over_ws_limit)
    note: str = ""


def _text(category: str, payload: bytes, **kw) -> Hostile:
    return Hostile(category, [frame_bytes(OP_TEXT, payload)], payload, **kw)


def _json(obj) -> bytes:
    return json.dumps(obj, ensure_ascii=False).encode("utf-8")


FRAME_ANSWERED_TYPES = {"camera", "interaction_start", "interaction_end", "viewport", "transfer_function",
                        "quality_policy", "clip_planes", "still"}


def _unique_pairs(pairs):
    keys = [k for k, _ in pairs]
    if len(keys) != len(set(keys)):
        raise ValueError("duplicate key")
    return dict(pairs)


def _reject_constant(name):
    raise ValueError(f"{name} is not JSON")


def strict_parse(payload: bytes):
    """The message as a strict JSON reader sees it (no NaN, no duplicate keys), or None."""
    try:
        return json.loads(payload.decode("utf-8"), object_pairs_hook=_unique_pairs,
                          parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None


def classify(h: Hostile) -> Hostile:
    """Fill in what a message that may be valid after all can get: no text answer for a
    valid request answered by frames, a 1000 close for a valid `close`."""
    if h.binary or h.expect_code or h.expect_close:
        return h
    obj = strict_parse(h.payload)
    if isinstance(obj, dict) and isinstance(obj.get("type"), str):
        if obj["type"] in FRAME_ANSWERED_TYPES:
            h.needs_answer = False
        if obj["type"] == "close":
            h.may_close_normally = True
    return h


# --- Valid messages, the material for the rest ------------------------------------------

CAMERA = {"eye": [300.0, 250.0, 350.0], "target": [64.0, 64.0, 64.0], "up": [0, 1, 0],
          "projection": "perspective", "fov_y_deg": 30}


def valid_messages(rng: random.Random, msg_id) -> List[dict]:
    """One valid message of every type (cheap to render: small images)."""
    w, h = rng.choice([(64, 64), (128, 96), (200, 150)])
    return [
        {"type": "hello", "id": msg_id, "protocol": 1, "client": "soak"},
        {"type": "list_volumes", "id": msg_id},
        {"type": "open_volume", "id": msg_id, "name": "builtin:demo"},
        {"type": "camera", "id": msg_id, "camera": dict(CAMERA)},
        {"type": "camera", "id": msg_id, "camera": {"eye": [0, 0, 400], "target": [64, 64, 64], "up": [0, 1, 0],
                                                    "projection": "orthographic", "height": 200}},
        {"type": "interaction_start", "id": msg_id},
        {"type": "interaction_end", "id": msg_id},
        {"type": "viewport", "id": msg_id, "image": {"width": w, "height": h}},
        {"type": "transfer_function", "id": msg_id, "transfer_function": {"preset": "ct_bone"}},
        {"type": "transfer_function", "id": msg_id,
         "transfer_function": {"points": [[0, 0, 0, 0, 0], [128, 1, 0.5, 0.2, 0.5], [255, 1, 1, 1, 1]],
                               "opacity_unit": 1.0}},
        {"type": "quality_policy", "id": msg_id, "mode": "automatic", "target_frame_ms": 40},
        {"type": "quality_policy", "id": msg_id, "mode": "explicit", "quality": {"step": 2.0, "image_scale": 0.5}},
        {"type": "clip_planes", "id": msg_id, "clip_planes": [{"point": [64, 64, 64], "normal": [0, 0, 1]}]},
        {"type": "clip_planes", "id": msg_id, "clip_planes": []},
        {"type": "still", "id": msg_id, "image": {"width": w, "height": h}},
        {"type": "get_state", "id": msg_id},
        {"type": "close", "id": msg_id},
    ]


def _paths(obj, prefix=()):
    """Every (path, value) inside a JSON value, the root included."""
    yield prefix, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, prefix + (i,))


def _set(obj, path, value):
    if not path:
        return value
    target = obj
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return obj


def _delete(obj, path):
    target = obj
    for key in path[:-1]:
        target = target[key]
    if isinstance(target, dict):
        del target[path[-1]]
    else:
        target.pop(path[-1])
    return obj


WRONG_VALUES = [None, True, False, 0, -1, 1.5, -0.0, "", "x", "hello", [], {}, [1, 2, 3], {"a": 1},
                [[[]]], "1", "true", "null", 2 ** 31, -2 ** 31 - 1, "é", "\u2028", "🦀"]

NON_ASCII = ["é", "ñandú", "日本語のボリューム", "🧠🦴", "Ωmega", "\u202eevil", "a\u0301", "\ufeffbom",
             "\u00a0nbsp", "\U0010ffff", "ß/ü.nrrd", "Ä" * 300, "\u0000", "\u001f", "\ud83d"]

HUGE_NUMBERS = ["1e308", "-1e308", "1e400", "-1e400", "1e-400", "18446744073709551616",
                "-9223372036854775809", "9223372036854775807", "123456789012345678901234567890",
                "4294967296", "-2147483649", "0.0000000000000000000001", "-0", "1E+999999", "2e-308",
                "99999999999999999999999999999999999999999999999999e999"]

NON_FINITE = ["NaN", "Infinity", "-Infinity", "nan", "inf", "-inf", "+1", "0x10", ".5", "1.", "01", "1e", "--1"]

INVALID_UTF8 = [b"\xff", b"\xfe", b"\xc3", b"\xc3\x28", b"\xc0\xaf", b"\xe0\x80\xaf", b"\xed\xa0\x80",
                b"\xf4\x90\x80\x80", b"\xf8\x88\x80\x80\x80", b"\x80", b"\xe2\x82", b"\xf0\x9f\x98"]


def _placeholder_replace(obj, path, raw: str) -> bytes:
    """obj serialised with the value at path replaced by raw JSON text (NaN, 1e400, ...)."""
    marker = "\u0001SOAK\u0001"
    text = json.dumps(_set(obj, path, marker), ensure_ascii=False)
    return text.replace(json.dumps(marker, ensure_ascii=False), raw, 1).encode("utf-8")


class Generator:
    """Hostile messages from one seeded random stream."""

    def __init__(self, rng: random.Random, categories: Optional[str] = None):
        self.rng = rng
        self.counter = 0
        self.kinds: List[Tuple[str, float, Callable[[], Hostile]]] = [
            ("wrong_kind", 10, self.wrong_kind),
            ("missing_field", 5, self.missing_field),
            ("extra_field", 5, self.extra_field),
            ("huge_number", 8, self.huge_number),
            ("non_finite", 6, self.non_finite),
            ("deep_nesting", 4, self.deep_nesting),
            ("long_string", 4, self.long_string),
            ("non_ascii", 8, self.non_ascii),
            ("invalid_utf8", 6, self.invalid_utf8),
            ("duplicate_key", 5, self.duplicate_key),
            ("binary", 4, self.binary),
            ("fragmented", 5, self.fragmented),
            ("oversized", 1.5, self.oversized),
            ("over_ws_limit", 0.3, self.over_ws_limit),
            ("not_a_message", 5, self.not_a_message),
            ("unknown_type", 3, self.unknown_type),
            ("garbage", 5, self.garbage),
            ("mutation", 18, self.mutation),
            ("frame_violation", 2, self.frame_violation),
            ("valid", 4, self.valid),
        ]
        if categories:
            wanted = set(categories.split(","))
            unknown = wanted - {name for name, _, _ in self.kinds}
            if unknown:
                raise SystemExit(f"unknown categories {sorted(unknown)}; known: {[n for n, _, _ in self.kinds]}")
            self.kinds = [k for k in self.kinds if k[0] in wanted]
        self.total_weight = sum(w for _, w, _ in self.kinds)

    def next(self, allow_close: bool = True) -> Hostile:
        r = self.rng.uniform(0, self.total_weight)
        for name, weight, make in self.kinds:
            r -= weight
            if r <= 0:
                h = make()
                break
        else:
            h = self.kinds[-1][2]()
        if not allow_close and h.may_close_normally:
            return self.next(allow_close)
        return h

    def _id(self):
        self.counter += 1
        return self.counter

    def _base(self) -> dict:
        return json.loads(json.dumps(self.rng.choice(valid_messages(self.rng, self._id()))))

    def valid(self) -> Hostile:
        m = self._base()
        return classify(_text("valid", _json(m)))

    def wrong_kind(self) -> Hostile:
        m = self._base()
        path, _ = self.rng.choice(list(_paths(m))[1:])
        return classify(_text("wrong_kind", _json(_set(m, path, self.rng.choice(WRONG_VALUES))),
                              note=f"at {list(path)}"))

    def missing_field(self) -> Hostile:
        m = self._base()
        paths = [p for p, _ in _paths(m)][1:]
        path = self.rng.choice(paths)
        return classify(_text("missing_field", _json(_delete(m, path)), note=f"without {list(path)}"))

    def extra_field(self) -> Hostile:
        m = self._base()
        containers = [p for p, v in _paths(m) if isinstance(v, dict)]
        path = self.rng.choice(containers)
        key = self.rng.choice(["nmae", "extra", "é", "", "type2", "__proto__", "constructor", "a" * 100])
        target = m
        for k in path:
            target = target[k]
        target[key] = self.rng.choice(WRONG_VALUES)
        return classify(_text("extra_field", _json(m), note=f"{key!r} in {list(path)}"))

    def huge_number(self) -> Hostile:
        m = self._base()
        numeric = [p for p, v in _paths(m) if isinstance(v, (int, float)) and not isinstance(v, bool)]
        path = self.rng.choice(numeric) if numeric else ("id",)
        raw = self.rng.choice(HUGE_NUMBERS)
        payload = _placeholder_replace(m, path, raw)
        h = _text("huge_number", payload, note=f"{raw} at {list(path)}")
        # Python reads 1e400 as inf and 1E+999999 too; the server must refuse or accept, never crash.
        return classify(h)

    def non_finite(self) -> Hostile:
        m = self._base()
        leaves = [p for p, v in _paths(m) if not isinstance(v, (dict, list))]
        path = self.rng.choice(leaves)
        raw = self.rng.choice(NON_FINITE)
        return _text("non_finite", _placeholder_replace(m, path, raw), expect_code="malformed_json",
                     note=f"{raw} at {list(path)}")

    def deep_nesting(self) -> Hostile:
        depth = self.rng.choice([MAX_DEPTH + 1, MAX_DEPTH + 8, 100, 1000, 10000, 30000])
        opener, closer = self.rng.choice([("[", "]"), ('{"a":', "}")])
        m = self._base()
        containers = [p for p, v in _paths(m)][1:] or [("extra",)]
        path = self.rng.choice(containers)
        payload = _placeholder_replace(m, path, opener * depth + "1" + closer * depth)
        # Deeper than 32 is too_large by protocol/README.md, whatever else is wrong with it.
        return _text("deep_nesting", payload, expect_code="too_large", note=f"depth {depth} at {list(path)}")

    def long_string(self) -> Hostile:
        m = self._base()
        strings = [p for p, v in _paths(m) if isinstance(v, str)] + [("name",), ("client",), ("id",)]
        path = self.rng.choice(strings)
        n = self.rng.choice([65, 257, 1025, 4096, 60000, 70000, 200000])
        value = self.rng.choice(["a", "é", "/", "../", "\\"]) * n
        payload = _json(_set(m, path, value))
        expect = "too_large" if len(payload) > MAX_MESSAGE_BYTES else None
        return classify(_text("long_string", payload, expect_code=expect, note=f"{n}× at {list(path)}"))

    def non_ascii(self) -> Hostile:
        m = self._base()
        strings = [p for p, v in _paths(m) if isinstance(v, str)]
        value = self.rng.choice(NON_ASCII)
        if self.rng.random() < 0.3:  # a non-ASCII key instead
            m[value] = 1
            note = f"key {value!r}"
        else:
            path = self.rng.choice(strings + [("name",), ("client",), ("id",)])
            _set(m, path, value if self.rng.random() < 0.7 else value + "/" + value)
            note = f"{value!r} at {list(path)}"
        try:
            payload = _json(m)
        except UnicodeEncodeError:
            # A lone surrogate cannot be UTF-8: it goes as the JSON escape \ud83d instead.
            payload = json.dumps(m, ensure_ascii=True).encode()
        return classify(_text("non_ascii", payload, note=note))

    def invalid_utf8(self) -> Hostile:
        m = self._base()
        strings = [p for p, v in _paths(m) if isinstance(v, str)]
        bad = self.rng.choice(INVALID_UTF8)
        marker = "SOAKMARK"
        path = self.rng.choice(strings)
        payload = _json(_set(m, path, marker)).replace(marker.encode(), b"ok" + bad + b"ok", 1)
        # protocol/README.md: the WebSocket layer fails the connection with 1007 before the
        # parser sees the text; there is no malformed_json answer.
        return _text("invalid_utf8", payload, expect_close=(1007,), note=f"{bad!r} at {list(path)}")

    def duplicate_key(self) -> Hostile:
        m = self._base()
        key = self.rng.choice(list(m.keys()))
        text = _json(m).decode()
        dup = json.dumps(key) + ":" + json.dumps(self.rng.choice([m[key], None, 1, "x"]))
        payload = ("{" + dup + "," + text[1:]).encode()
        return _text("duplicate_key", payload, expect_code="bad_field", note=f"top-level {key!r} twice")

    def binary(self) -> Hostile:
        n = self.rng.choice([0, 1, 8, 100, 4096, 70000])
        choice = self.rng.random()
        if choice < 0.3:
            payload = _json(self._base())            # a valid request, but binary
        elif choice < 0.5:
            payload = b"VCF1" + bytes(self.rng.getrandbits(8) for _ in range(min(n, 64)))
        else:
            payload = self.rng.randbytes(n)
        return Hostile("binary", [frame_bytes(OP_BINARY, payload)], payload, binary=True,
                       expect_code="bad_message", note=f"{len(payload)} bytes")

    def fragmented(self) -> Hostile:
        inner = self.rng.choice([self.valid, self.wrong_kind, self.non_ascii, self.garbage, self.binary])()
        if inner.binary:
            op = OP_BINARY
        else:
            op = OP_TEXT
        payload = inner.payload
        pieces = self.rng.randint(2, min(12, max(2, len(payload))))
        cuts = sorted(self.rng.sample(range(1, max(2, len(payload))), min(pieces - 1, max(1, len(payload) - 1))))
        parts = [payload[a:b] for a, b in zip([0] + cuts, cuts + [len(payload)])]
        frames = []
        for i, part in enumerate(parts):
            frames.append(frame_bytes(op if i == 0 else OP_CONTINUATION, part, fin=i == len(parts) - 1))
            if i < len(parts) - 1 and self.rng.random() < 0.3:
                frames.append(frame_bytes(OP_PING, b"soak"))   # control frames may interleave
        inner.category = "fragmented"
        inner.frames = frames
        inner.note = f"{len(parts)} fragments of {inner.note or 'a message'}"
        return inner

    def oversized(self) -> Hostile:
        n = self.rng.choice([MAX_MESSAGE_BYTES + 1, MAX_MESSAGE_BYTES * 2, MAX_MESSAGE_BYTES * 15])
        m = self._base()
        m["client" if m["type"] == "hello" else "pad"] = ""
        base = _json(m)
        payload = base[:-1] + b", \"x\": \"" + b"z" * max(0, n - len(base) - 9) + b"\"}"
        return _text("oversized", payload, expect_code="too_large", note=f"{len(payload)} bytes")

    def over_ws_limit(self) -> Hostile:
        payload = b'{"type": "hello", "client": "' + b"z" * (WS_LIMIT_BYTES + 10) + b'"}'
        # protocol/README.md: over the WebSocket limit the connection closes. The server sends
        # 1009 and closes while most of the message is still unread in its socket, so its TCP
        # answers the rest of our write with a reset, which can beat the close frame to us.
        return _text("over_ws_limit", payload, expect_close=(1009,), may_drop=True, note=f"{len(payload)} bytes")

    def not_a_message(self) -> Hostile:
        payload = self.rng.choice([b"[]", b"[1,2]", b"42", b'"hello"', b"null", b"true", b"{}",
                                   b'{"id": 1}', b'{"type": 1}', b'{"type": null}', b'{"type": ["hello"]}',
                                   b'{"type": {"hello": 1}}', b'[{"type": "hello", "protocol": 1}]',
                                   b'{"type": true, "id": 3}', b"  {}  "])
        return _text("not_a_message", payload, expect_code="bad_message")

    def unknown_type(self) -> Hostile:
        name = self.rng.choice(["rotate", "", "HELLO", "hello ", "Hello", "é", "close\u0000", "get-state",
                                "x" * 1000, "日本", "error", "state", "frame"])
        payload = _json({"type": name, "id": self._id()})
        return _text("unknown_type", payload, expect_code="unknown_type", note=repr(name[:40]))

    def garbage(self) -> Hostile:
        n = self.rng.choice([0, 1, 2, 10, 100, 1000])
        alphabet = '{}[]":,0123456789.eE+-truefalsn \t\n\\/uéü日🦀\u0000\u0001'
        payload = "".join(self.rng.choice(alphabet) for _ in range(n)).encode("utf-8")
        return classify(_text("garbage", payload, note=f"{len(payload)} bytes"))

    def mutation(self) -> Hostile:
        data = bytearray(_json(self._base()))
        ops = []
        for _ in range(self.rng.randint(1, 4)):
            op = self.rng.randrange(6)
            pos = self.rng.randrange(len(data) + 1)
            if op == 0 and pos < len(data):
                data[pos] ^= 1 << self.rng.randrange(8)
                ops.append(f"flip@{pos}")
            elif op == 1:
                b = self.rng.choice([b'"', b"{", b"}", b"[", b"]", b",", b":", b"\\", b"\x00", b"\xff", b"\xc3",
                                     b"9", b"-", b"e", b"\xc3\xa9", b"\\u0000", b"\\ud800", b"NaN"])
                data[pos:pos] = b
                ops.append(f"insert {b!r}@{pos}")
            elif op == 2 and pos < len(data):
                del data[pos:pos + self.rng.randint(1, 8)]
                ops.append(f"delete@{pos}")
            elif op == 3:
                a = self.rng.randrange(len(data) + 1)
                chunk = data[min(a, pos):max(a, pos)][:64]
                data[pos:pos] = chunk
                ops.append(f"repeat {len(chunk)}@{pos}")
            elif op == 4 and pos < len(data):
                data[pos] = self.rng.getrandbits(8)
                ops.append(f"byte@{pos}")
            else:
                data = data[:pos]
                ops.append(f"truncate@{pos}")
        payload = bytes(data)
        try:
            payload.decode("utf-8")
        except UnicodeDecodeError:
            return _text("mutation", payload, expect_close=(1007,), note=", ".join(ops))
        return classify(_text("mutation", payload, note=", ".join(ops)))

    def frame_violation(self) -> Hostile:
        """Broken WebSocket framing: RFC 6455 says fail the connection, 1002."""
        text = _json(self._base())
        kind = self.rng.randrange(6)
        if kind == 0:
            frames, note = [frame_bytes(OP_CONTINUATION, text)], "a continuation with nothing to continue"
        elif kind == 1:
            frames, note = [frame_bytes(OP_TEXT, text, mask=False)], "an unmasked client frame"
        elif kind == 2:
            frames, note = [frame_bytes(self.rng.choice([3, 4, 5, 6, 7, 0xB, 0xF]), text)], "a reserved opcode"
        elif kind == 3:
            frames, note = [frame_bytes(OP_TEXT, text, rsv=self.rng.choice([1, 2, 4]))], "RSV bits without an extension"
        elif kind == 4:
            frames, note = [frame_bytes(OP_PING, b"p" * 126)], "a ping over 125 bytes"
        else:
            frames = [frame_bytes(OP_TEXT, text[:5], fin=False), frame_bytes(OP_TEXT, text[5:])]
            note = "a new text frame inside a fragmented message"
        return Hostile("frame_violation", frames, text, expect_close=(1002,), note=note)
