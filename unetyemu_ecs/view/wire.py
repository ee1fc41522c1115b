"""The web view's wire protocol: JSON text messages and framed binary messages over one WebSocket.

Server -> page, text (JSON objects with a ``type``):

- ``scene`` (once, on connect): protocol version, ``mode`` (``live`` / ``replay``), world name, the
  city's bounds [m, ENU], the ground colour, and per vehicle its name, kind, colour, half extents
  and sensors (:mod:`.scene`).
- ``state`` (at most :data:`STATE_HZ` per second of wall time): sim time, real-time factor, and per
  vehicle pose (ENU position [m], ENU->FLU quaternion xyzw), speed, altitude, battery, mode and
  mission step; the newest events; in a replay, the player's state (:mod:`.frames`).

Server -> page, binary: ``uint32 little-endian n``, then ``n`` bytes of a JSON header (padded with
spaces to a multiple of 4, so the payload that follows is 4-byte aligned for typed arrays), then
the payload. Headers have a ``type``:

- ``mesh`` (once, on connect): ``vertices`` V, ``triangles`` T; payload float32 (V, 3) ENU vertices
  [m], uint32 (T, 3) vertex indices, uint8 (T, 3) RGB per triangle (padded to a multiple of 4).
- ``lidar``: ``vehicle``, ``t`` [s, sim], ``points`` N; payload float32 (N, 3) ENU [m] points,
  decimated to at most :data:`MAX_LIDAR_POINTS`.
- ``image``: ``vehicle``, ``sensor``, ``t``, ``width``, ``height``; payload rgb8 rows (depth
  images arrive as a grey scale, near bright).

Page -> server, text (JSON; anything else, or anything malformed, is counted and ignored):
``{"type": "select", "vehicle": NAME | null}`` (whose LiDAR and camera to send),
``{"type": "lidar", "mode": "selected" | "all" | "off"}``, and in a replay
``{"type": "play"}``, ``{"type": "pause"}``, ``{"type": "seek", "t": SECONDS}``,
``{"type": "speed", "x": FACTOR}``.
"""

from __future__ import annotations

import json
import struct
from typing import Any

PROTOCOL_VERSION = 1
WS_PATH = "/ws"
STATE_HZ = 25.0                  # state messages (and the server's tick) per second of wall time
MAX_LIDAR_POINTS = 30_000        # per cloud, after decimation
MAX_IMAGE_PIXELS = 640 * 480     # larger images are decimated before sending
MAX_CLIENT_MESSAGE_BYTES = 4096  # what the page sends is tiny; anything larger closes the connection
LIDAR_MODES = ("selected", "all", "off")
MAX_REPLAY_SPEED = 64.0


def text(message: dict[str, Any]) -> str:
    """A text message: compact JSON (NaN and infinities become null: the page's JSON cannot hold them)."""
    try:
        return json.dumps(message, separators=(",", ":"), allow_nan=False)
    except ValueError:              # a non-finite number somewhere: replace them all (rare, so not first)
        return json.dumps(_finite(message), separators=(",", ":"), allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if value == value and abs(value) != float("inf") else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def binary(header: dict[str, Any], *payloads: bytes | memoryview) -> bytes:
    """A binary message: the length of the JSON header, the header padded to a multiple of 4, the
    payloads one after the other (each must be a multiple of 4 bytes long, except the last)."""
    head = text(header).encode()
    head += b" " * (-len(head) % 4)
    return b"".join([struct.pack("<I", len(head)), head, *payloads])


def parse_binary(message: bytes) -> tuple[dict[str, Any], memoryview]:
    """The header and payload of a binary message (tests; the page does the same in JavaScript)."""
    (n,) = struct.unpack_from("<I", message, 0)
    return json.loads(message[4:4 + n]), memoryview(message)[4 + n:]


def parse_client_message(message: str | bytes) -> dict[str, Any] | None:
    """A message from the page as a dict with a known ``type`` and well-formed fields, or None when it
    is anything else (binary, not JSON, not an object, an unknown type, a field of the wrong kind)."""
    if not isinstance(message, str) or len(message) > MAX_CLIENT_MESSAGE_BYTES:
        return None
    try:
        msg = json.loads(message)
    except ValueError:
        return None
    if not isinstance(msg, dict):
        return None
    kind = msg.get("type")
    if kind == "select":
        vehicle = msg.get("vehicle")
        return {"type": kind, "vehicle": vehicle} if vehicle is None or isinstance(vehicle, str) else None
    if kind == "lidar":
        return {"type": kind, "mode": msg["mode"]} if msg.get("mode") in LIDAR_MODES else None
    if kind in ("play", "pause"):
        return {"type": kind}
    if kind in ("seek", "speed"):
        key = "t" if kind == "seek" else "x"
        value = msg.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value or abs(value) == float("inf"):
            return None
        if kind == "speed" and not 0.0 < value <= MAX_REPLAY_SPEED:
            return None
        return {"type": kind, key: float(value)}
    return None


__all__ = ["LIDAR_MODES", "MAX_CLIENT_MESSAGE_BYTES", "MAX_IMAGE_PIXELS", "MAX_LIDAR_POINTS", "MAX_REPLAY_SPEED",
           "PROTOCOL_VERSION", "STATE_HZ", "WS_PATH", "binary", "parse_binary", "parse_client_message", "text"]
