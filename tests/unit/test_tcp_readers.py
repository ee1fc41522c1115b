"""Telling a client that stopped reading from one that reads: the kernel's receive queues of loopback connections."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from unetyemu_ecs.transport.tcp_readers import PROC_NET_TCP, StalledReaders, client_receive_queues

HEADER = "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode\n"


def table(path: Path, rows: list[tuple[str, str, str, int, int]]) -> str:
    """Write a /proc/net/tcp-like table: (local end, remote end, state, tx bytes, rx bytes) per socket."""
    lines = [f"{i:4d}: {local} {remote} {state} {tx:08X}:{rx:08X} 00:00000000 00000000     0        0 1 1"
             for i, (local, remote, state, tx, rx) in enumerate(rows)]
    path.write_text(HEADER + "\n".join(lines) + "\n")
    return str(path)


SERVER = "0100007F:1F90"            # 127.0.0.1:8080
CLIENT_A, CLIENT_B = "0100007F:C350", "0100007F:C351"


def test_only_the_client_ends_of_established_connections_to_the_server_are_read(tmp_path):
    path = table(tmp_path / "tcp", [
        ("0100007F:1F90", "00000000:0000", "0A", 0, 0),         # the listening socket
        (SERVER, CLIENT_A, "01", 4096, 0),                      # the server's end of A: not what is read
        (CLIENT_A, SERVER, "01", 0, 123456),                    # A's end: 123456 bytes unread
        (CLIENT_B, SERVER, "06", 0, 99),                        # B's end in TIME_WAIT: gone
        ("0100007F:C352", "0100007F:1F91", "01", 0, 7),         # a connection to another port
    ])
    assert client_receive_queues(8080, path) == {CLIENT_A: 123456}
    assert client_receive_queues(8081, path) == {"0100007F:C352": 7}
    assert client_receive_queues(8080, str(tmp_path / "absent")) is None          # not Linux: unknown


def test_a_client_is_stalled_once_its_queue_stayed_full_for_stall_s_and_reads_again_when_it_empties(tmp_path):
    path = tmp_path / "tcp"
    readers = StalledReaders(8080, stall_s=2.0, table=str(path))
    table(path, [(CLIENT_A, SERVER, "01", 0, 5000), (CLIENT_B, SERVER, "01", 0, 0)])
    readers.sample(10.0)
    assert (readers.connected, readers.stalled, readers.all_stalled) == (2, 0, False)
    table(path, [(CLIENT_A, SERVER, "01", 0, 9000), (CLIENT_B, SERVER, "01", 0, 0)])
    readers.sample(11.0)
    table(path, [(CLIENT_A, SERVER, "01", 0, 9000), (CLIENT_B, SERVER, "01", 0, 300)])
    readers.sample(11.9)
    assert readers.stalled == 0                                   # A full for 1.9 s, B empty 0.9 s ago
    readers.sample(12.0)
    assert (readers.stalled, readers.all_stalled) == (1, False)   # A: 2 s without once being empty
    readers.sample(13.0)
    assert (readers.stalled, readers.all_stalled) == (2, True)    # B too (empty last at 11 s): nobody reads
    table(path, [(CLIENT_A, SERVER, "01", 0, 0), (CLIENT_B, SERVER, "01", 0, 300)])
    readers.sample(13.1)
    assert (readers.stalled, readers.all_stalled) == (1, False)   # A read everything: it reads again
    table(path, [(CLIENT_A, SERVER, "01", 0, 0)])
    readers.sample(13.2)
    assert (readers.connected, readers.stalled) == (1, 0)         # B closed its connection
    table(path, [])
    readers.sample(13.3)
    assert (readers.connected, readers.all_stalled) == (0, False)  # nobody connected: nobody stalled
    path.unlink()
    readers.sample(13.4)
    assert (readers.connected, readers.stalled, readers.all_stalled) == (None, None, False)


def test_a_stall_time_that_is_not_positive_is_refused():
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="stall_s must be > 0 s"):
            StalledReaders(8080, stall_s=bad)


@pytest.mark.skipif(not Path(PROC_NET_TCP).exists(), reason="needs Linux's /proc/net/tcp")
def test_a_real_loopback_client_that_does_not_read_holds_bytes_in_its_queue_until_it_reads():
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)) as client:
            conn, _ = server.accept()
            with conn:
                conn.sendall(b"x" * 20000)
                client_end = f":{client.getsockname()[1]:04X}"

                def unread() -> list[int]:
                    return [n for end, n in client_receive_queues(port).items() if end.endswith(client_end)]

                for _ in range(200):                  # the bytes reach the client's queue at once (loopback)
                    if unread() == [20000]:
                        break
                assert unread() == [20000]
                got = 0
                while got < 20000:
                    got += len(client.recv(65536))
                assert unread() == [0]
