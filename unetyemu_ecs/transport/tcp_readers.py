"""Whether the clients of a loopback TCP server still read what it sends: the kernel's receive queues (Linux).

A WebSocket server whose client stops reading (a frozen browser tab, a stopped debugger, a Foxglove
window behind a modal dialog) only sees its own send buffers fill, and the protocol has no
acknowledgement to say so. The server here listens on 127.0.0.1, so both ends of every connection are
sockets of this machine's network namespace, and ``/proc/net/tcp`` lists the client's end too: its
receive queue (``rx_queue``, bytes the kernel holds that the client's program has not read). A
client that reads empties it within moments of each message; one that stopped keeps it non-zero.
:class:`StalledReaders` calls a client stalled when every sample of its receive queue over
``stall_s`` seconds (wall) was non-zero. Where ``/proc/net/tcp`` cannot be read (not Linux) it
knows nothing and reports ``None``.
"""

from __future__ import annotations

PROC_NET_TCP = "/proc/net/tcp"          # IPv4 sockets of this network namespace (the server binds 127.0.0.1)
ESTABLISHED = "01"                      # the st column
STALL_S = 2.0                           # [s, wall] a receive queue never empty this long: the client stopped


def client_receive_queues(server_port: int, table: str = PROC_NET_TCP) -> dict[str, int] | None:
    """Bytes waiting unread in the receive queue of each established client connection to ``server_port``
    on this machine, keyed by the client's end (``"HEXIP:HEXPORT"`` as the table writes it); None when
    the table cannot be read."""
    try:
        with open(table, encoding="ascii", errors="replace") as f:
            lines = f.read().splitlines()[1:]
    except OSError:
        return None
    server_end = f":{server_port:04X}"
    queues: dict[str, int] = {}
    for line in lines:
        # sl local_address rem_address st tx_queue:rx_queue ...
        fields = line.split()
        if len(fields) < 5 or fields[3] != ESTABLISHED or not fields[2].endswith(server_end):
            continue
        try:
            queues[fields[1]] = int(fields[4].partition(":")[2], 16)
        except ValueError:
            continue
    return queues


class StalledReaders:
    """Tracks the clients of a server on ``server_port``: :meth:`sample` at a steady pace (a few times a
    second); ``stalled`` and ``connected`` are the counts after the newest sample (None: unknown)."""

    def __init__(self, server_port: int, stall_s: float = STALL_S, table: str = PROC_NET_TCP) -> None:
        if not stall_s > 0.0:
            raise ValueError(f"StalledReaders: stall_s must be > 0 s, got {stall_s!r}")
        self.server_port = server_port
        self.stall_s = float(stall_s)
        self.table = table
        self._last_empty_s: dict[str, float] = {}      # client end -> when its receive queue was last seen empty
        self.connected: int | None = None
        self.stalled: int | None = None

    def sample(self, now_s: float) -> None:
        """Read the receive queues at ``now_s`` [s, wall, monotonic]."""
        queues = client_receive_queues(self.server_port, self.table)
        if queues is None:
            self.connected = self.stalled = None
            return
        seen = {end: (now_s if unread == 0 else self._last_empty_s.get(end, now_s)) for end, unread in queues.items()}
        self._last_empty_s = seen
        self.connected = len(seen)
        self.stalled = sum(now_s - t >= self.stall_s for t in seen.values())

    @property
    def all_stalled(self) -> bool:
        """Clients are connected and none of them reads."""
        return bool(self.connected) and self.stalled == self.connected


__all__ = ["STALL_S", "StalledReaders", "client_receive_queues"]
