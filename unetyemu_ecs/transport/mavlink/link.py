"""One UDP link of a drone's endpoint (``api`` or ``gcs``): its socket, parser, peers and sender."""

from __future__ import annotations

import errno
import socket
import sys
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink2

from ..api import TransportError
from .codec import DatagramParser, RxCounters, signing_timestamp

MAX_PEERS = 4
PEER_TIMEOUT_S = 10.0            # wall clock: a peer silent this long gets no more telemetry
RX_DATAGRAMS_PER_WAKE = 64       # bounded receive work per socket per loop turn
# Receive budget per link (token bucket, wall clock). MAVSDK at full tilt sends ~100 datagrams/s (a 50 Hz
# offboard stream, heartbeats, commands, a mission upload), a ground station far fewer; beyond the budget
# the link stops reading until it refills and the kernel drops the excess, so a flooded port costs the
# simulation loop a bounded share of the interpreter (Python threads share one GIL).
RX_RATE_PER_S = 1000.0
RX_BURST = 200
RX_RESUME_TOKENS = 32            # a paused link reads again once this many datagrams are allowed
SOCKET_BUFFER_BYTES = 1 << 20
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)     # Linux: each datagram carries the socket's drop count
_DROP_COUNT_SPACE = socket.CMSG_SPACE(4)


@dataclass
class TxCounters:
    tx_messages: int = 0
    tx_errors: int = 0


class Link:
    """A bound UDP socket with its own parser, peer list and sending ``MAVLink`` object.

    ``send(msg)`` packs ``msg`` with the endpoint's system/component id (and signature) and sends it
    to the default destination and every live peer. Peers are added by :meth:`adopt` only after a
    valid message addressed to us (the endpoint decides), never by junk.
    """

    def __init__(self, name: str, vehicle: str, bind: str, local_port: int, remote: tuple[str, int],
                 sysid: int, compid: int, signing_key: bytes | None) -> None:
        self.name = name
        self.vehicle = vehicle
        self.local = (bind, local_port)
        self.remote = remote
        self.rx = RxCounters()
        self.tx = TxCounters()
        self.parser = DatagramParser(self.rx)
        self._mav = mavlink2.MAVLink(None, sysid, compid)
        if signing_key is not None:
            self._mav.signing.secret_key = signing_key
            self._mav.signing.sign_outgoing = True
            self._mav.signing.link_id = 0 if name == "api" else 1
            self._mav.signing.timestamp = signing_timestamp()
        self.peers: dict[tuple[str, int], float] = {}
        self.sock: socket.socket | None = None
        self._tokens = float(RX_BURST)
        self._refilled_s: float | None = None
        self.paused_until_s = 0.0        # wall clock: the receive budget is spent until then

    def open(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)   # no SO_REUSEADDR: a taken port is an error
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
            sock.bind(self.local)
            try:                               # count what the kernel drops while the link is paused
                sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:                    # not Linux: rx_kernel_dropped stays 0
                pass
        except OSError as exc:
            sock.close()
            host, port = self.local
            if exc.errno == errno.EADDRINUSE:
                raise TransportError(f"mavlink endpoint of {self.vehicle}: UDP {host}:{port} ({self.name} link) is "
                                     f"already in use (another simulator or PX4 SITL?)") from None
            raise TransportError(f"mavlink endpoint of {self.vehicle}: cannot bind UDP {host}:{port} "
                                 f"({self.name} link): {exc.strerror}") from None
        sock.setblocking(False)
        self.sock = sock

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def receive(self, now_s: float) -> list[tuple[bytes, tuple[str, int]]]:
        """The datagrams waiting on the socket, at most RX_DATAGRAMS_PER_WAKE and within the receive
        budget; when the budget is spent, ``paused_until_s`` says when to read again (counted in
        ``rx_rate_limited``)."""
        out: list[tuple[bytes, tuple[str, int]]] = []
        if self.sock is None:
            return out
        if self._refilled_s is not None:
            self._tokens = min(float(RX_BURST), self._tokens + (now_s - self._refilled_s) * RX_RATE_PER_S)
        self._refilled_s = now_s
        for _ in range(min(RX_DATAGRAMS_PER_WAKE, int(self._tokens))):
            try:
                data, ancillary, _, addr = self.sock.recvmsg(65535, _DROP_COUNT_SPACE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:            # ICMP port unreachable from an earlier send, etc.
                continue
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                    self.rx.rx_kernel_dropped = int.from_bytes(value[:4], sys.byteorder)    # cumulative, per socket
            out.append((data, addr[:2]))
        self._tokens -= len(out)
        if self._tokens < 1.0:
            self.paused_until_s = now_s + (RX_RESUME_TOKENS - self._tokens) / RX_RATE_PER_S
            self.rx.rx_rate_limited += 1
        return out

    def adopt(self, addr: tuple[str, int], now_s: float) -> None:
        """Remember ``addr`` as a peer (it sent a valid message addressed to us)."""
        if addr == self.remote or addr in self.peers:
            self.peers[addr] = now_s if addr != self.remote else now_s
            return
        if len(self.peers) >= MAX_PEERS:
            oldest = min(self.peers, key=self.peers.__getitem__)
            del self.peers[oldest]
        self.peers[addr] = now_s

    def expire(self, now_s: float) -> None:
        for addr in [a for a, t in self.peers.items() if now_s - t > PEER_TIMEOUT_S]:
            del self.peers[addr]

    def destinations(self) -> list[tuple[str, int]]:
        return [self.remote, *(a for a in self.peers if a != self.remote)]

    def send(self, msg: mavlink2.MAVLink_message, to: tuple[str, int] | None = None) -> None:
        """Pack ``msg`` (our ids, sequence and signature) and send it to ``to`` or to every destination."""
        if self.sock is None:
            return
        try:
            buf = msg.pack(self._mav)
        except Exception:              # noqa: BLE001 - a value out of its field's range
            self.tx.tx_errors += 1
            return
        self._mav.seq = (self._mav.seq + 1) % 256
        for dest in ([to] if to is not None else self.destinations()):
            try:
                self.sock.sendto(buf, dest)
                self.tx.tx_messages += 1
            except OSError:
                self.tx.tx_errors += 1

    def counters(self) -> dict[str, int]:
        return {**self.rx.as_dict(), "tx_messages": self.tx.tx_messages, "tx_errors": self.tx.tx_errors,
                "peers": len(self.peers)}


__all__ = ["Link"]
