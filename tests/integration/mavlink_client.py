"""A small pymavlink client for the MAVLink endpoint tests: a UDP socket bound where the endpoint
sends (the client's side of a link), a pymavlink encoder, and helpers that step the simulation
while waiting for an answer (the simulation runs on the test's thread; no timing assumptions:
waits are bounded by sim steps, with a generous wall-clock cap)."""

from __future__ import annotations

import random
import socket
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from unetyemu_ecs.transport.mavlink.codec import DatagramParser, RxCounters, signing_timestamp


def port_block(n: int, rng: random.Random | None = None) -> int:
    """A base port such that base .. base + n - 1 are all free on 127.0.0.1 (UDP)."""
    rng = rng or random.Random()
    for _ in range(200):
        base = rng.randrange(20000, 60000 - n)
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free block of UDP ports")


def world_text(ports: dict[str, int], n_drones: int = 2, signing: str = "", vehicle_extra: str = "") -> str:
    """A flat world with ``n_drones`` drones on the ground, each with a ``mavlink`` component."""
    lines = []
    for i in range(n_drones):
        sign = f", signing: {signing}" if signing else ""
        lines.append(
            f"  - {{name: d{i + 1}, type: quadrotor, preset: small, pose: {{position_m: [{5 * i}, 0, 0.2]}}, "
            f"{vehicle_extra}"
            f"components: {{mavlink: {{instance: {i}, api_local_base: {ports['api_local']}, "
            f"api_remote_base: {ports['api_remote']}, gcs_local_base: {ports['gcs_local']}, "
            f"gcs_remote: {ports['gcs_remote']}{sign}}}}}}}")
    return ("world: {name: mavlink_test, physics_hz: 240, seed: 3}\n"
            "scene: {generator: none, ground_size_m: 400}\n"
            "vehicles:\n" + "\n".join(lines) + "\n")


def free_ports(n_drones: int = 2) -> dict[str, int]:
    rng = random.Random()
    out: dict[str, int] = {}
    taken: set[int] = set()
    for name, n in (("api_local", n_drones), ("api_remote", n_drones), ("gcs_local", n_drones), ("gcs_remote", 1)):
        while True:
            base = port_block(n, rng)
            if not taken.intersection(range(base, base + n)):
                break
        taken.update(range(base, base + n))
        out[name] = base
    return out


class Client:
    """One MAVLink peer: bound at ``port`` (where the endpoint sends), talking to ``target`` port."""

    def __init__(self, port: int, target: int | None = None, sysid: int = 245, compid: int = 190,
                 key: bytes | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.target = target
        self.mav = mavlink2.MAVLink(None, sysid, compid)
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = 7
            self.mav.signing.timestamp = signing_timestamp()
        self.parser = DatagramParser(RxCounters())
        self.inbox: list[tuple[Any, tuple[str, int]]] = []

    def close(self) -> None:
        self.sock.close()

    def pack(self, msg: Any) -> bytes:
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        return buf

    def send(self, msg: Any, port: int | None = None) -> None:
        self.raw(self.pack(msg), port)

    def raw(self, data: bytes, port: int | None = None) -> None:
        self.sock.sendto(data, ("127.0.0.1", port if port is not None else self.target))

    def poll(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            for msg, _, signed in self.parser.frames(data):
                msg.signed_frame = signed            # the frame carried a signature (not verified here)
                self.inbox.append((msg, addr))

    def take(self, mtype: str, cond=lambda m: True) -> Any | None:
        for k, (msg, _) in enumerate(self.inbox):
            if msg.get_type() == mtype and cond(msg):
                del self.inbox[k]
                return msg
        return None

    def drain(self) -> None:
        self.poll()
        self.inbox.clear()

    def command_long(self, command: int, *params: float, target_system: int = 1, target_component: int = 1) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.send(mavlink2.MAVLink_command_long_message(target_system, target_component, command, 0, *p))


def wait_for(sim: Any, clients: list[Client] | Client, mtype: str, cond=lambda m: True, *, steps: int = 2400,
             chunk: int = 12, wall_cap_s: float = 60.0) -> Any | None:
    """Step ``sim`` (``chunk`` steps at a time, at most ``steps``) until one of ``clients`` got a
    ``mtype`` message satisfying ``cond``; returns it, or None."""
    clients = clients if isinstance(clients, list) else [clients]
    t_end = time.monotonic() + wall_cap_s
    done = 0
    while True:
        sim.flush_transports(5.0)
        for c in clients:
            c.poll()
            m = c.take(mtype, cond)
            if m is not None:
                return m
        if done >= steps or time.monotonic() > t_end:
            return None
        sim.step(chunk)
        done += chunk
