"""The built-in 3D web view: live (``view=PORT``) in headless Chromium and over a plain WebSocket, and replay.

The browser test drives ``chromium`` over the DevTools protocol (:mod:`.cdp_browser`): two
screenshots a few seconds of sim time apart must show the vehicles moved, and the page must log no
error. The protocol tests read the WebSocket directly: the scene once, states, LiDAR clouds that
decode to finite points around the vehicle, camera images; a page that never reads must not stop the
run; garbage must not hurt the server. The replay tests serve a recorded bag and seek in it.
Nothing here asserts timing: the sim runs at about real time where a page watches, and every wait
is for a condition (with a generous limit), not for a duration.
"""

from __future__ import annotations

import io
import json
import os
import signal
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.sync.client import connect

from unetyemu_ecs import Simulation, load_world
from unetyemu_ecs.cli import main as cli_main
from unetyemu_ecs.transport.api import TransportError
from unetyemu_ecs.view import wire
from unetyemu_ecs.view.replay import LOOKBACK_S, ReplayError, open_replay
from unetyemu_ecs.view.server import ViewServer

from ..conftest import REPO_ROOT, WORLDS, unetyemu_command
from .cdp_browser import HeadlessChromium, find_chromium

SCREENSHOT = REPO_ROOT / "docs" / "images" / "view.png"     # rewritten only with UNETYEMU_UPDATE_SCREENSHOT=1
WAIT_S = 120.0               # limit of every wait for a condition (a busy 2-core machine is slow, not stuck)


class LiveRun:
    """The delivery scenario with a view, stepping at about real time on a thread of its own."""

    def __init__(self, duration_s: float = 600.0) -> None:
        self.sim = Simulation(load_world(WORLDS / "urban_delivery.yaml"), view=0)
        self.view = self.sim.transports["view"]
        self.ws_url = self.view.url.replace("http://", "ws://") + "ws"
        self.thread = threading.Thread(target=self.sim.run, kwargs={"duration": duration_s, "rate": 1.0},
                                       name="test-view-sim", daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.sim.stop()
        self.thread.join(60)
        self.sim.close()


@pytest.fixture(scope="class")
def live():
    """One live run for the tests of :class:`TestLive`, stopped after them: esper's world is global to the
    process, so no other simulation may be built while it steps."""
    run = LiveRun()
    yield run
    run.close()


def receive(ws, until, timeout_s: float = WAIT_S) -> dict:
    """Read messages into {"state": [...], "lidar": [(header, payload)], "image": [...]} until ``until(got)``."""
    got: dict = {"state": [], "lidar": [], "image": [], "other": []}
    deadline = time.monotonic() + timeout_s
    while not until(got):
        assert time.monotonic() < deadline, f"timed out; got {[(k, len(v)) for k, v in got.items()]}"
        message = ws.recv(timeout=WAIT_S)
        if isinstance(message, str):
            msg = json.loads(message)
            got["state" if msg["type"] == "state" else "other"].append(msg)
        else:
            header, payload = wire.parse_binary(message)
            got.get(header["type"], got["other"]).append((header, bytes(payload)))
    return got


# -- live: the page in a browser, and the protocol with a plain WebSocket ------------------------
class TestLive:
    def test_a_page_gets_the_scene_once_then_states_clouds_and_images(self, live):
        world = load_world(WORLDS / "urban_delivery.yaml")
        with connect(live.ws_url, max_size=None) as ws:
            scene = json.loads(ws.recv(timeout=WAIT_S))
            assert scene["type"] == "scene" and scene["protocol"] == wire.PROTOCOL_VERSION and scene["mode"] == "live"
            assert [v["name"] for v in scene["vehicles"]] == [e.name for e in world.vehicles]
            assert {v["name"]: v["kind"] for v in scene["vehicles"]}["truck1"] == "car"
            assert "lidar" in {v["name"]: v["sensors"] for v in scene["vehicles"]}["drone1"]
            header, payload = wire.parse_binary(ws.recv(timeout=WAIT_S))
            assert header["type"] == "mesh"
            nv, nt = header["vertices"], header["triangles"]
            vertices = np.frombuffer(payload[:12 * nv], "<f4").reshape(nv, 3)
            triangles = np.frombuffer(payload[12 * nv:12 * nv + 12 * nt], "<u4").reshape(nt, 3)
            assert nt > 1000 and np.isfinite(vertices).all() and triangles.max() < nv
            assert len(payload) >= 12 * nv + 15 * nt                                   # + one RGB per triangle

            ws.send(json.dumps({"type": "select", "vehicle": "drone1"}))
            # (early in the run: drone1 is still low enough for its LiDAR to reach the ground)
            got = receive(ws, lambda g: len(g["state"]) >= 3 and any(h["points"] > 0 for h, _ in g["lidar"]))
            assert not got["other"], "the scene and the mesh are sent once"
            times = [s["t"] for s in got["state"]]
            assert times == sorted(times)
            last = got["state"][-1]
            assert [v["name"] for v in last["vehicles"]] == [e.name for e in world.vehicles]
            drone1 = last["vehicles"][0]
            assert drone1["battery"] is not None and drone1["mode"] and len(drone1["p"]) == 3 and len(drone1["q"]) == 4
            assert last["vehicles"][-1]["battery"] is None and last["vehicles"][-1]["mode"] in ("driving", "parked")
            header, payload = [x for x in got["lidar"] if x[0]["points"] > 0][-1]
            assert header["vehicle"] == "drone1"
            points = np.frombuffer(payload, "<f4").reshape(-1, 3)
            assert len(points) == header["points"] and np.isfinite(points).all()
            # in the world frame, around drone1 (its LiDAR reaches 30 m), mostly on or above the ground
            assert np.linalg.norm(points - np.asarray(drone1["p"]), axis=1).max() < 40.0
            assert np.percentile(points[:, 2], 5) > -0.5
            assert {h["vehicle"] for h, _ in got["lidar"]} == {"drone1"}              # only the selected one's

            ws.send(json.dumps({"type": "select", "vehicle": "drone3"}))
            got = receive(ws, lambda g: g["image"])
            header, payload = got["image"][-1]
            assert header["vehicle"] == "drone3" and header["sensor"] == "camera"
            assert len(payload) == header["width"] * header["height"] * 3 == 320 * 240 * 3
            ws.send(json.dumps({"type": "select", "vehicle": "drone2"}))           # a depth camera: grey
            got = receive(ws, lambda g: any(h["vehicle"] == "drone2" for h, _ in g["image"]))
            header, payload = [i for i in got["image"] if i[0]["vehicle"] == "drone2"][-1]
            assert header["sensor"] == "depth_camera"
            px = np.frombuffer(payload, np.uint8).reshape(header["height"], header["width"], 3)
            assert (px[:, :, 0] == px[:, :, 1]).all()
        counters = live.view.counters()
        assert counters["clients_total"] >= 1 and counters["frames_sent"] > 0 and counters["url"] == live.view.url


    def test_the_server_serves_the_page_and_refuses_what_it_should(self, live):
        base = live.view.url
        with urllib.request.urlopen(base, timeout=WAIT_S) as r:
            assert r.status == 200 and r.headers["Content-Type"].startswith("text/html")
            assert b'type="importmap"' in r.read()
        with urllib.request.urlopen(base + "vendor/three.module.min.js", timeout=WAIT_S) as r:
            assert r.headers["Content-Type"].startswith("text/javascript") and len(r.read()) > 100_000
        for path, code in (("nope.html", 404), ("../pyproject.toml", 404), ("%2e%2e/pyproject.toml", 404)):
            with pytest.raises(urllib.error.HTTPError) as e:
                urllib.request.urlopen(base + path, timeout=WAIT_S)
            assert e.value.code == code, path
        port = live.view.port
        with pytest.raises(urllib.error.HTTPError) as e:          # another name for this host (DNS rebinding)
            urllib.request.urlopen(urllib.request.Request(base, headers={"Host": f"example.com:{port}"}), timeout=WAIT_S)
        assert e.value.code == 421
        with pytest.raises(Exception, match="403"):              # a WebSocket opened by another web site
            connect(live.ws_url, origin="http://example.com", open_timeout=WAIT_S)
        # garbage: not HTTP, a bad upgrade, nonsense and oversized messages on a WebSocket
        for junk in (b"\x16\x03\x01\x00\xa5garbage\r\n\r\n", b"GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n",
                     b"POST / HTTP/1.1\r\n\r\n", os.urandom(3000)):
            with socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) as s:
                s.sendall(junk)
                s.shutdown(socket.SHUT_WR)
                s.recv(4096)
        bad_before = live.view.counters()["bad_messages"]
        with connect(live.ws_url, max_size=None) as ws:
            for junk in ("not json", b"\x00\xff", '{"type": "seek", "t": "soon"}', '{"type": 7}', "[]"):
                ws.send(junk)
            ws.send(json.dumps({"type": "select", "vehicle": "no_such_vehicle"}))
            receive(ws, lambda g: len(g["state"]) >= 2)                     # still served
            ws.send("x" * (wire.MAX_CLIENT_MESSAGE_BYTES + 1))             # too large: the server hangs up
            with pytest.raises(Exception):
                receive(ws, lambda g: False, timeout_s=30)
        assert live.view.counters()["bad_messages"] >= bad_before + 5
        with urllib.request.urlopen(base, timeout=WAIT_S) as r:               # and it still serves
            assert r.status == 200
        assert live.thread.is_alive()

    @pytest.mark.skipif(find_chromium() is None, reason="chromium is not installed (the test setup installs it with apt)")
    def test_the_page_shows_the_vehicles_moving_without_console_errors(self, live):
        from PIL import Image, ImageChops

        world = load_world(WORLDS / "urban_delivery.yaml")
        with HeadlessChromium(width=1280, height=800) as browser:
            browser.navigate(live.view.url)
            state = "window.unetyemuView && window.unetyemuView.state()"
            browser.wait_for(f"{state} && {state}.sceneLoaded && {state}.states > 5", WAIT_S)
            browser.evaluate("window.unetyemuView.select('drone3')")                 # the one with the RGB camera
            browser.evaluate("(() => { const s = document.getElementById('lidarmode'); s.value = 'all';"
                             " s.dispatchEvent(new Event('change')); })()")
            browser.wait_for(f"{state}.images > 0 && {state}.lidarFrames > 0 && {state}.rtf !== null", WAIT_S)
            first = browser.evaluate(f"{state}")
            renders = first["renders"]
            browser.wait_for(f"{state}.renders > {renders}", WAIT_S)
            shot1 = browser.screenshot()
            before = browser.evaluate(f"{state}")
            # a few seconds of sim time later (however fast this machine runs it)
            browser.wait_for(f"{state}.simTime > {before['simTime'] + 3.0}", WAIT_S)
            browser.wait_for(f"{state}.renders > {browser.evaluate(f'{state}.renders')}", WAIT_S)
            shot2 = browser.screenshot()
            after = browser.evaluate(f"{state}")
            box = browser.evaluate("(() => { const r = document.getElementById('viewport').getBoundingClientRect();"
                                   " return [r.left, r.top, r.right, r.bottom].map(Math.round); })()")
            errors = browser.console_errors()

        assert errors == [], "the page logged errors:\n" + "\n".join(errors)
        assert after["connected"] and after["mode"] == "live" and after["world"] == "urban_delivery"
        assert after["meshTriangles"] > 1000                                          # the city arrived
        assert set(after["vehicles"]) == {e.name for e in world.vehicles}
        assert after["rtf"] > 0 and after["simTime"] > before["simTime"]
        assert after["imageVehicle"] == "drone3" and after["lidarFrames"] > 0
        moved = {name: float(np.linalg.norm(np.subtract(after["vehicles"][name]["p"], v["p"])))
                 for name, v in before["vehicles"].items()}
        assert moved["truck1"] > 1.0, moved                     # driving its route at 8 m/s
        assert moved["drone2"] > 1.0, moved                     # climbing to 62 m
        assert moved["car1"] < 0.05, moved                      # parked
        assert after["vehicles"]["drone1"]["mode"] and after["vehicles"]["drone1"]["battery"] > 0.5
        # the 3D view's pixels changed between the two screenshots
        img1, img2 = (Image.open(io.BytesIO(s)).convert("RGB") for s in (shot1, shot2))
        assert img1.size == img2.size
        diff = np.asarray(ImageChops.difference(img1.crop(box), img2.crop(box))).max(axis=2)
        assert np.count_nonzero(diff > 24) > 50, "the 3D view looks the same in both screenshots"
        # the README's screenshot: `UNETYEMU_UPDATE_SCREENSHOT=1 python3 -m pytest tests/integration/test_view.py`
        # (a plain test run leaves the checkout as it was)
        if os.environ.get("UNETYEMU_UPDATE_SCREENSHOT") == "1":
            SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
            SCREENSHOT.write_bytes(shot2)


def _stalled_page(port: int) -> socket.socket:
    """A WebSocket client that completes the handshake, asks for drone3's camera and every LiDAR cloud, and
    then never reads another byte."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)
    assert head.startswith(b"HTTP/1.1 101"), head
    for ask in ({"type": "select", "vehicle": "drone3"}, {"type": "lidar", "mode": "all"}):   # the heaviest page
        payload, mask = json.dumps(ask).encode(), os.urandom(4)
        s.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
    return s


def test_a_page_that_never_reads_does_not_stop_the_run():
    with Simulation(load_world(WORLDS / "urban_delivery.yaml"), view=0) as sim:
        view = sim.transports["view"]
        stalled = [_stalled_page(view.port) for _ in range(2)]
        try:
            sim.run(duration=4.0)                                     # as fast as it can
            assert sim.sim_time_s == pytest.approx(4.0, abs=0.01)
            counters = view.counters()
            assert counters["clients"] == 2
            # each page holds at most one message per channel: nothing piles up for a page that does not read
            assert counters["messages_waiting"] <= 2 * 3
            # and the images and clouds no page asked for stayed in the simulation's process
            assert counters["worker"]["samples_held_back"] > 0
            # once their sockets' buffers are full and they took no state for a second, nothing is sent for them
            deadline = time.monotonic() + WAIT_S
            while (counters := view.counters())["clients_watching"]:
                assert time.monotonic() < deadline, counters
                sim.run(duration=0.25)
            sim.run(duration=1.0)
            after = view.counters()
            held_back = after["worker"]["snapshots_held_back"] - counters["worker"]["snapshots_held_back"]
            assert held_back >= 230                                   # of the 240 steps (a mission status crosses)
            with connect(view.url.replace("http://", "ws://") + "ws", max_size=None) as ws:  # others are served
                receive(ws, lambda g: g["state"])
        finally:
            for s in stalled:
                s.close()


def test_run_with_view_prints_the_url_and_counts_into_the_summary(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli_main(["run", str(WORLDS / "empty.yaml"), "--duration", "0.3", "--out", str(out), "--quiet",
                     "--view", "0"]) == 0
    printed = [line for line in capsys.readouterr().err.splitlines() if line.startswith("view: ")]
    assert len(printed) == 1 and printed[0].startswith("view: http://127.0.0.1:")
    counters = json.loads((out / "summary.json").read_text())["transports"]["view"]
    assert counters["url"] == printed[0].removeprefix("view: ")
    assert counters["clients_total"] == 0 and counters["frames_sent"] == 0 and counters["errors"] == []


def test_a_port_in_use_is_a_transport_error_naming_it():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(TransportError, match=f"127.0.0.1:{port}.*in use"):
            Simulation(load_world(WORLDS / "empty.yaml"), view=port)


def test_no_view_without_a_port_and_a_bad_port_is_refused():
    with Simulation(load_world(WORLDS / "empty.yaml")) as sim:
        assert "view" not in sim.transports
    with pytest.raises((TransportError, ValueError)):
        Simulation(load_world(WORLDS / "empty.yaml"), view=70000)


# -- replay ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """Three seconds of the delivery scenario recorded, in a run directory with its summary.json."""
    out = tmp_path_factory.mktemp("viewrec")
    assert cli_main(["run", str(WORLDS / "urban_delivery.yaml"), "--duration", "3", "--out", str(out / "run"),
                     "--quiet", "--record"]) == 0
    return out / "run" / "recording"


def test_a_replay_serves_the_recording_and_seeks(recording, tmp_path):
    with pytest.raises(ReplayError, match="--world"):
        open_replay(recording, world=tmp_path / "missing.yaml")
    source = open_replay(recording)              # the city from the run's summary.json
    server = ViewServer(source, 0)
    server.start()
    try:
        assert source.scene.layout is not None and not source.scene.note
        with connect(server.url.replace("http://", "ws://") + "ws", max_size=None) as ws:
            scene = json.loads(ws.recv(timeout=WAIT_S))
            assert scene["mode"] == "replay" and scene["world"] == "urban_delivery"
            assert scene["start_s"] < scene["end_s"] == pytest.approx(3.0, abs=0.05)
            assert wire.parse_binary(ws.recv(timeout=WAIT_S))[0]["triangles"] > 1000
            ws.send(json.dumps({"type": "pause"}))
            ws.send(json.dumps({"type": "select", "vehicle": "drone1"}))
            world = load_world(WORLDS / "urban_delivery.yaml")
            assert [v["name"] for v in scene["vehicles"]] == [e.name for e in world.vehicles]
            positions = {}
            for t in (2.0, 0.5):
                ws.send(json.dumps({"type": "seek", "t": t}))
                # the newest cloud at or before t (from the second before it), and the state at t
                got = receive(ws, lambda g: any(s["t"] == t for s in g["state"]) and any(
                    t - LOOKBACK_S <= h["t"] <= t for h, _ in g["lidar"]))
                state = [s for s in got["state"] if s["t"] == t][-1]
                assert state["replay"]["playing"] is False
                truck = {v["name"]: v for v in state["vehicles"]}["truck1"]
                positions[t] = truck["p"]
                header, payload = [x for x in got["lidar"] if t - LOOKBACK_S <= x[0]["t"] <= t][-1]
                assert header["vehicle"] == "drone1"
                points = np.frombuffer(payload, "<f4").reshape(-1, 3)
                assert np.isfinite(points).all() and len(points) > 0
                drone1 = {v["name"]: v for v in state["vehicles"]}["drone1"]
                assert np.linalg.norm(points - np.asarray(drone1["p"]), axis=1).max() < 40.0
            assert positions[2.0][0] - positions[0.5][0] > 5.0        # the truck drove east meanwhile
            ws.send(json.dumps({"type": "speed", "x": 4}))
            ws.send(json.dumps({"type": "play"}))
            got = receive(ws, lambda g: any(s["replay"]["playing"] and s["t"] > 0.6 for s in g["state"]))
            assert got["state"][-1]["replay"]["speed"] == 4.0
    finally:
        server.stop()
        source.rec.close()


@pytest.mark.skipif(find_chromium() is None, reason="chromium is not installed (the test setup installs it with apt)")
def test_the_replay_page_plays_pauses_and_seeks(recording):
    source = open_replay(recording)
    server = ViewServer(source, 0)
    server.start()
    state = "window.unetyemuView.state()"
    try:
        with HeadlessChromium(width=1024, height=700) as browser:
            browser.navigate(server.url)
            browser.wait_for(f"window.unetyemuView && {state}.sceneLoaded && {state}.replay !== null", WAIT_S)
            assert browser.evaluate("document.getElementById('player').hidden") is False
            browser.evaluate("document.getElementById('play').click()")                     # pause
            browser.wait_for(f"{state}.replay.playing === false", WAIT_S)
            for t in (2.5, 1.0):                                                              # the slider
                browser.evaluate(f"(() => {{ const s = document.getElementById('seek'); s.value = {t};"
                                 " s.dispatchEvent(new Event('change')); })()")
                browser.wait_for(f"{state}.simTime === {t}", WAIT_S)
            truck = browser.evaluate(f"{state}.vehicles.truck1.p")
            browser.evaluate("document.getElementById('play').click()")                     # play on
            browser.wait_for(f"{state}.replay.playing && {state}.simTime > 1.5", WAIT_S)
            browser.wait_for(f"{state}.vehicles.truck1.p[0] > {truck[0] + 1.0}", WAIT_S)
            errors = browser.console_errors()
        assert errors == [], "the page logged errors:\n" + "\n".join(errors)
    finally:
        server.stop()
        source.rec.close()


def test_the_view_command_replays_until_ctrl_c(recording):
    proc = subprocess.Popen([*unetyemu_command(), "view", str(recording / "recording.mcap"), "--port", "0"],
                            cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        assert line.startswith("view: http://127.0.0.1:"), line + proc.stderr.read() if proc.poll() is not None else line
        url = line.split(": ", 1)[1].strip()
        with urllib.request.urlopen(url, timeout=WAIT_S) as r:
            assert r.status == 200
        proc.send_signal(signal.SIGINT)
        assert proc.wait(WAIT_S) == 0
        assert "stopped" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_view_command_explains_a_missing_or_invalid_recording(tmp_path, capsys):
    assert cli_main(["view", str(tmp_path / "missing")]) == 2
    assert "no recording at" in capsys.readouterr().err
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("hello")
    assert cli_main(["view", str(tmp_path / "junk")]) == 2
    assert "not a recording" in capsys.readouterr().err
    (tmp_path / "bad.mcap").write_bytes(b"\x89MCAP0\r\n" + os.urandom(200))
    assert cli_main(["view", str(tmp_path / "bad.mcap")]) == 2
    assert "cannot read the recording" in capsys.readouterr().err
