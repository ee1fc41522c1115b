"""The web view's page, vendored JavaScript, wire protocol and frame building, without a browser or a run."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unetyemu_ecs.frames import quat_xyzw_from_euler_rpy
from unetyemu_ecs.sensors.camera import image
from unetyemu_ecs.sensors.lidar import POINT_DTYPE, pointcloud2_of_points
from unetyemu_ecs.view import frames, wire
from unetyemu_ecs.view.server import STATIC_DIR

from ..conftest import REPO_ROOT

WEB = REPO_ROOT / "web"
VENDOR = STATIC_DIR / "vendor"


class _Urls(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self.importmap = ""
        self._in_importmap = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self.urls += [v for k, v in a.items() if k in ("src", "href") and v]
        self._in_importmap = tag == "script" and a.get("type") == "importmap"

    def handle_data(self, data: str) -> None:
        if self._in_importmap:
            self.importmap += data

    def handle_endtag(self, tag: str) -> None:
        self._in_importmap = False


def _is_local(url: str) -> bool:
    return not re.match(r"^([a-z][a-z0-9+.-]*:|//)", url, re.I) or url.startswith("data:")


def test_the_page_loads_only_files_the_package_ships():
    page = _Urls()
    page.feed((STATIC_DIR / "index.html").read_text(encoding="utf-8"))
    imports = json.loads(page.importmap)["imports"]
    urls = page.urls + list(imports.values())
    assert urls and "view.js" in urls and "favicon.svg" in urls        # a favicon: no 404 in the console
    for url in urls:
        assert _is_local(url), f"index.html loads {url} from elsewhere (no CDN: the page works offline)"
        target = STATIC_DIR / url.removeprefix("./")
        assert target.exists(), f"index.html names {url}, which static/ does not have"
    # every module the page imports resolves to a vendored file through the import map
    for js in [STATIC_DIR / "view.js", *VENDOR.rglob("*.js")]:
        for spec in re.findall(r"""(?:from|import)\s*["']([^"']+)["']""", js.read_text(encoding="utf-8")):
            if spec.startswith("."):
                assert (js.parent / spec).resolve().is_file(), f"{js.name} imports {spec}"
            else:
                prefix = max((k for k in imports if spec == k or (k.endswith("/") and spec.startswith(k))), key=len,
                             default=None)
                assert prefix is not None, f"{js.name} imports {spec!r}, which the import map does not map"
                assert (STATIC_DIR / (imports[prefix] + spec[len(prefix):]).removeprefix("./")).is_file(), spec


def test_the_vendored_three_is_the_pinned_npm_release():
    pinned = json.loads((WEB / "package.json").read_text())["devDependencies"]["three"]
    assert re.fullmatch(r"\d+\.\d+\.\d+", pinned), f"three must be pinned to an exact version, not {pinned!r}"
    lock = json.loads((WEB / "package-lock.json").read_text())
    assert lock["packages"]["node_modules/three"]["version"] == pinned
    vendored = json.loads((VENDOR / "VERSION.json").read_text())
    assert vendored["version"] == pinned, "run `npm ci && npm run build` in web/ after changing the pin"
    for dest in vendored["files"]:
        assert (VENDOR / dest).is_file(), dest


def test_the_package_data_ships_every_file_of_the_page():
    """pyproject.toml's package data must name every file under static/ (a wheel without the addons
    would serve a page that cannot load)."""
    import tomllib

    data = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    package = STATIC_DIR.parent
    shipped = {p for pattern in data.get("unetyemu_ecs.view", []) for p in package.glob(pattern) if p.is_file()}
    missing = sorted(str(p.relative_to(package)) for p in STATIC_DIR.rglob("*") if p.is_file() and p not in shipped)
    assert not missing, f"pyproject.toml [tool.setuptools.package-data] unetyemu_ecs.view leaves out {missing}"


@pytest.mark.slow
def test_the_vendored_files_are_byte_identical_to_the_npm_package(tmp_path):
    """``npm ci`` (the registry: network) in a copy of web/, then the build script's copies must match."""
    if shutil.which("npm") is None:
        pytest.skip("npm is not installed")
    web = tmp_path / "web"
    shutil.copytree(WEB, web, ignore=shutil.ignore_patterns("node_modules"))
    run = subprocess.run(["npm", "ci", "--no-audit", "--no-fund"], cwd=web, capture_output=True, text=True, timeout=300)
    if run.returncode != 0:
        pytest.skip(f"npm ci failed (no registry?): {run.stderr[-500:]}")
    three = web / "node_modules" / "three"
    files = json.loads((VENDOR / "VERSION.json").read_text())["files"]
    for dest, src in files.items():
        assert (VENDOR / dest).read_bytes() == (three / src).read_bytes(), f"vendor/{dest} differs from three/{src}"


# -- the wire protocol ---------------------------------------------------------------------------
def test_binary_messages_align_their_payload_and_parse_back():
    pts = np.arange(12, dtype="<f4")
    for name in ("a", "ab", "abc", "abcd"):
        msg = wire.binary({"type": "x", "vehicle": name}, pts.tobytes())
        header, payload = wire.parse_binary(msg)
        assert header == {"type": "x", "vehicle": name}
        assert (len(msg) - len(payload)) % 4 == 0
        assert np.array_equal(np.frombuffer(payload, "<f4"), pts)


def test_text_messages_turn_non_finite_numbers_into_null():
    assert json.loads(wire.text({"a": float("nan"), "b": [float("inf"), 1.5]})) == {"a": None, "b": [None, 1.5]}


@pytest.mark.parametrize("message, expected", [
    ('{"type": "select", "vehicle": "drone1"}', {"type": "select", "vehicle": "drone1"}),
    ('{"type": "select", "vehicle": null}', {"type": "select", "vehicle": None}),
    ('{"type": "lidar", "mode": "all"}', {"type": "lidar", "mode": "all"}),
    ('{"type": "seek", "t": 3}', {"type": "seek", "t": 3.0}),
    ('{"type": "speed", "x": 2.5}', {"type": "speed", "x": 2.5}),
    ('{"type": "pause", "extra": 1}', {"type": "pause"}),
    ('{"type": "select", "vehicle": 3}', None), ('{"type": "lidar", "mode": "some"}', None),
    ('{"type": "seek", "t": "1"}', None), ('{"type": "seek", "t": NaN}', None), ('{"type": "seek", "t": true}', None),
    ('{"type": "speed", "x": 0}', None), ('{"type": "speed", "x": 1e9}', None), ('{"type": "nope"}', None),
    ("[1, 2]", None), ("not json", None), (b"\x00\x01", None), ("x" * 10_000, None),
])
def test_what_the_page_sends_is_checked(message, expected):
    assert wire.parse_client_message(message) == expected


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.text(max_size=200), st.binary(max_size=200),
                 st.dictionaries(st.text(max_size=8), st.one_of(st.none(), st.booleans(), st.floats(), st.text(max_size=8),
                                                               st.integers()), max_size=4).map(json.dumps)))
def test_garbage_from_a_page_never_raises(message):
    msg = wire.parse_client_message(message)
    assert msg is None or msg["type"] in ("select", "lidar", "play", "pause", "seek", "speed")


# -- frames ---------------------------------------------------------------------------------------
def test_cloud_points_move_from_the_sensor_frame_into_enu():
    pts = np.zeros(3, dtype=POINT_DTYPE)
    pts["x"], pts["y"], pts["z"] = [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, float("nan")]
    msg = pointcloud2_of_points(pts, 1.0, "d/lidar_link")
    xyz = frames.cloud_xyz(msg)
    assert xyz.shape == (2, 3)                                        # the NaN point is dropped
    # body at (10, 20, 30) yawed 90 deg left; sensor 0.5 m above base_link
    q = np.asarray(quat_xyzw_from_euler_rpy(0.0, 0.0, np.pi / 2)).ravel()
    out = frames.cloud_points_enu(xyz, (10.0, 20.0, 30.0), q, (0.0, 0.0, 0.5))
    assert out.dtype == np.float32
    assert np.allclose(out, [[10.0, 21.0, 30.5], [8.0, 20.0, 30.5]], atol=1e-5)   # forward is north, left is west


def test_lidar_messages_are_capped():
    pts = np.random.default_rng(1).normal(size=(wire.MAX_LIDAR_POINTS * 2 + 7, 3)).astype(np.float32)
    header, payload = wire.parse_binary(frames.lidar_message("d", 1.0, pts))
    assert header["points"] <= wire.MAX_LIDAR_POINTS and len(payload) == 12 * header["points"]


def test_images_of_every_encoding_become_rgb8():
    rgb = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)
    assert np.array_equal(frames.image_rgb8(image(0.0, "f", 6, 4, "rgb8", rgb)), rgb)
    assert np.array_equal(frames.image_rgb8(image(0.0, "f", 6, 4, "bgr8", rgb[:, :, ::-1].copy())), rgb)
    depth = np.full((4, 6), np.inf, dtype=np.float32)
    depth[0, 0] = 0.0
    grey = frames.image_rgb8(image(0.0, "f", 6, 4, "32FC1", depth))
    assert grey.shape == (4, 6, 3) and grey[0, 0, 0] == 255 and grey[1, 1, 0] == 0      # near bright, no return black
    assert frames.image_rgb8(SimpleNamespace(height=4, width=6, step=18, encoding="yuv422", data=rgb.ravel(),
                                             is_bigendian=0)) is None
    assert frames.image_rgb8(SimpleNamespace(height=4, width=6, step=18, encoding="rgb8", data=rgb.ravel()[:5],
                                             is_bigendian=0)) is None               # truncated: nothing, no error
    big = np.zeros((1000, 1000, 3), np.uint8)
    header, payload = wire.parse_binary(frames.image_message("d", "camera", 0.0, big))
    assert header["width"] * header["height"] <= wire.MAX_IMAGE_PIXELS
    assert len(payload) == header["width"] * header["height"] * 3


def test_mission_status_reads_as_one_line():
    assert frames.mission_text({"mission": "m", "state": "running", "step": 2, "steps": 8, "step_type": "cruise",
                                "stage": "fly"}) == "3/8 cruise (fly)"
    assert frames.mission_text({"mission": None, "state": "idle"}) == "idle"
    assert frames.mission_text({"mission": "m", "state": "failed", "reason": "low battery"}) == "failed: low battery"
    assert frames.mission_text(None) == ""


def test_a_frame_is_built_once_and_a_failing_build_gives_nothing():
    calls = []
    frame = frames.LazyFrame(1, 0.0, lambda: calls.append(1) or b"x")
    assert frame.get() == b"x" and frame.get() == b"x" and calls == [1]
    assert frames.LazyFrame(2, 0.0, lambda: 1 / 0).get() is None
