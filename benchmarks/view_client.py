"""A watcher in a process of its own, for benchmarks/test_bench_views.py: a Foxglove client or a web view page.

    python3 benchmarks/view_client.py foxglove ws://127.0.0.1:PORT [--stall]
    python3 benchmarks/view_client.py view ws://127.0.0.1:PORT/ws [--stall]

``foxglove`` (subprotocol foxglove.sdk.v1) subscribes to every advertised channel (as a Foxglove layout with 3D, Image and Plot
panels over everything would); ``view`` selects drone3 and asks for every LiDAR cloud (the page's
heaviest setting). Both print ``ready`` once subscribed, then read and count everything that arrives
(subscribing to channels as they are advertised). With ``--stall`` they stop reading on SIGUSR1 and
print ``stalled`` (a client or browser tab that froze after it had subscribed to everything). On
SIGTERM they print ``{"messages": N, "bytes": B}`` and exit. A process of its own, as a real viewer is: a
client thread inside the simulation's process would compete with it for the interpreter lock.
"""

from __future__ import annotations

import json
import signal
import sys
import time

from websockets.sync.client import connect


class Subscriber:
    """Subscribes a Foxglove connection to every channel it advertises, as they appear."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.channels: set[int] = set()

    def on_text(self, text: str) -> bool:
        """Handle one text frame; True when it advertised channels."""
        msg = json.loads(text)
        if msg.get("op") != "advertise":
            return False
        subs = []
        for channel in msg["channels"]:
            if channel["id"] not in self.channels:
                self.channels.add(channel["id"])
                subs.append({"id": len(self.channels), "channelId": channel["id"]})
        if subs:
            self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        return True


def main() -> int:
    kind, url = sys.argv[1], sys.argv[2]
    stall = "--stall" in sys.argv[3:]
    counts = {"messages": 0, "bytes": 0}

    def report(*_: object) -> None:
        print(json.dumps(counts), flush=True)
        sys.exit(0)

    signal.signal(signal.SIGTERM, report)
    freeze = []
    signal.signal(signal.SIGUSR1, lambda *_: freeze.append(True))
    protocols = ["foxglove.sdk.v1"] if kind == "foxglove" else None        # foxglove-sdk 0.30 speaks only this
    with connect(url, subprotocols=protocols, max_size=None, open_timeout=60) as ws:
        subscriber = Subscriber(ws)
        if kind == "foxglove":
            while True:                           # serverInfo, then the first advertise
                frame = ws.recv(timeout=60)
                if isinstance(frame, str) and subscriber.on_text(frame):
                    break
        else:
            ws.send(json.dumps({"type": "select", "vehicle": "drone3"}))
            ws.send(json.dumps({"type": "lidar", "mode": "all"}))
        print("ready", flush=True)
        while True:
            if stall and freeze:
                print("stalled", flush=True)
                while True:
                    time.sleep(3600)
            try:
                frame = ws.recv(timeout=0.1)
            except TimeoutError:
                continue
            counts["messages"] += 1
            counts["bytes"] += len(frame)
            if kind == "foxglove" and isinstance(frame, str):
                subscriber.on_text(frame)          # channels appear as topics are first published


if __name__ == "__main__":
    sys.exit(main())
