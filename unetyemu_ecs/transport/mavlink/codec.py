"""Robust per-datagram MAVLink parsing and our own signature check (pymavlink 2.4.50 underneath).

pymavlink's stream parser is built for serial lines: a stray magic byte or a truncated frame keeps
its buffer waiting for bytes that belong to the *next* datagram, unknown message ids are decoded
before any CRC or signature check, and its signature check records the stream timestamp before
comparing the HMAC (one forged frame with a huge timestamp locks the genuine sender out). So each
datagram is cut into frames here: at every magic byte the frame length is read from the header,
exactly that many bytes go to a freshly reset parser (signature checking off), and a frame that is
truncated, fails its CRC or has an unknown id is counted and the scan resumes one byte later, with a
bound on the work per datagram. Signatures are verified here (HMAC first, then the timestamp).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

# pymavlink skips every CRC check when MAV_IGNORE_CRC is set in the environment at import: never here.
mavlink2.MAVLINK_IGNORE_CRC = 0

MAGIC_V1, MAGIC_V2 = 0xFE, 0xFD
HEADER_V1, HEADER_V2 = 6, 10
CRC_LEN, SIGNATURE_LEN = 2, 13
IFLAG_SIGNED = 0x01
MAX_DATAGRAM = 4096              # MAVLink frames are <= 280 bytes; a bigger datagram is junk, dropped whole
MAX_FAILED_FRAMES = 16           # resync attempts per datagram before the rest is dropped (bounded work)
SIGNING_EPOCH_S = 1420070400     # 2015-01-01T00:00:00Z, the MAVLink signing timestamp's epoch
TIMESTAMP_WINDOW = 60 * 100_000  # a new stream's first timestamp may be this far from ours (60 s in 10 us)


def signing_timestamp(now_s: float | None = None) -> int:
    """MAVLink 2 signing timestamp: 10 us units since 2015-01-01 (wall clock)."""
    return int(((time.time() if now_s is None else now_s) - SIGNING_EPOCH_S) * 100_000)


def load_key(key_file: str | None, key_env: str | None, base_dir: Path | None = None) -> bytes:
    """The 32-byte secret: 32 raw bytes, 64 hex digits, or any other text hashed with SHA-256.
    Raises ValueError naming the source (never the key) when it is missing or empty."""
    if key_file is not None:
        path = Path(key_file)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise ValueError(f"signing key file {str(path)!r} cannot be read: {exc.strerror}") from None
        what = f"signing key file {str(path)!r}"
    else:
        text = os.environ.get(key_env or "")
        if text is None:
            raise ValueError(f"signing key environment variable {key_env!r} is not set")
        raw = text.encode()
        what = f"signing key environment variable {key_env!r}"
    if len(raw) == 32 and key_file is not None:
        return raw
    text = raw.strip()
    if not text:
        raise ValueError(f"{what} is empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    return hashlib.sha256(text).digest()


@dataclass
class RxCounters:
    """What one link received (run summary)."""

    rx_datagrams: int = 0
    rx_messages: int = 0
    bad_prefix: int = 0
    bad_crc: int = 0
    truncated: int = 0
    oversize: int = 0
    unknown_id: int = 0
    bad_signature: int = 0
    unsigned_rejected: int = 0
    not_for_us: int = 0
    parser_errors: int = 0
    rx_rate_limited: int = 0
    rx_kernel_dropped: int = 0     # datagrams the kernel dropped, its receive buffer full (Linux SO_RXQ_OVFL)

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))


@dataclass
class SignatureChecker:
    """Verifies incoming MAVLink 2 signatures with one secret: HMAC first, then a timestamp newer
    than the last accepted one of that (link id, system, component) stream."""

    key: bytes
    last: dict[tuple[int, int, int], int] = field(default_factory=dict)

    def check(self, frame: bytes) -> bool:
        if len(frame) < HEADER_V2 + CRC_LEN + SIGNATURE_LEN:
            return False
        digest = hashlib.sha256(self.key + frame[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, frame[-6:]):
            return False
        link_id = frame[-13]
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (link_id, frame[5], frame[6])
        last = self.last.get(stream)
        if last is None:
            if abs(stamp - signing_timestamp()) > TIMESTAMP_WINDOW:
                return False
        elif stamp <= last:
            return False
        if len(self.last) >= 64 and stream not in self.last:
            self.last.pop(next(iter(self.last)))
        self.last[stream] = stamp
        return True


class DatagramParser:
    """Cuts datagrams into MAVLink frames and decodes them; counts everything it drops."""

    def __init__(self, counters: RxCounters) -> None:
        self.counters = counters
        self._mav = mavlink2.MAVLink(None)
        self._mav.robust_parsing = True
        self._mav.signing.secret_key = None        # our own check (see SignatureChecker)

    def _decode(self, frame: bytes) -> mavlink2.MAVLink_message | None:
        mav = self._mav
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink2.HEADER_LEN_V1 + 2
        mav.have_prefix_error = False
        msgs = mav.parse_buffer(frame) or []
        return msgs[0] if len(msgs) == 1 else None

    def frames(self, data: bytes) -> Iterator[tuple[mavlink2.MAVLink_message, bytes, bool]]:
        """Yield (message, its frame bytes, signed) for each valid, known message in ``data``."""
        c = self.counters
        c.rx_datagrams += 1
        n = len(data)
        if n > MAX_DATAGRAM:
            c.oversize += 1
            return
        p, failures, junk = 0, 0, False
        while p < n:
            b = data[p]
            if b != MAGIC_V2 and b != MAGIC_V1:
                if not junk:
                    c.bad_prefix += 1
                    junk = True
                p += 1
                continue
            if failures >= MAX_FAILED_FRAMES:
                c.bad_prefix += 1
                return
            if b == MAGIC_V2:
                if p + 3 > n:
                    c.truncated += 1
                    return
                signed = bool(data[p + 2] & IFLAG_SIGNED)
                end = p + HEADER_V2 + data[p + 1] + CRC_LEN + (SIGNATURE_LEN if signed else 0)
            else:
                if p + 2 > n:
                    c.truncated += 1
                    return
                signed = False
                end = p + HEADER_V1 + data[p + 1] + CRC_LEN
            if end > n:
                c.truncated += 1
                failures += 1
                junk = True              # the bytes up to the next magic belong to this counted failure
                p += 1
                continue
            frame = bytes(data[p:end])
            try:
                msg = self._decode(frame)
            except Exception:                  # noqa: BLE001 - a parser bug must not end the endpoint
                msg = None
                c.parser_errors += 1
            if msg is None or msg.get_type() == "BAD_DATA" or isinstance(msg, mavlink2.MAVLink_unknown):
                if isinstance(msg, mavlink2.MAVLink_unknown):
                    c.unknown_id += 1
                elif msg is not None:
                    reason = getattr(msg, "reason", "")
                    if "CRC" in reason or "crc" in reason:
                        c.bad_crc += 1
                    else:
                        c.bad_prefix += 1
                failures += 1
                junk = True
                p += 1
                continue
            c.rx_messages += 1
            junk = False
            p = end
            yield msg, frame, signed


def addressed_to(msg: mavlink2.MAVLink_message, sysid: int, compid: int) -> bool:
    """True when ``msg`` is a broadcast or targets this system and component."""
    ts = getattr(msg, "target_system", 0)
    if ts not in (0, sysid):
        return False
    tc = getattr(msg, "target_component", 0)
    return tc in (0, compid)


__all__ = ["DatagramParser", "RxCounters", "SignatureChecker", "addressed_to", "load_key", "signing_timestamp"]
