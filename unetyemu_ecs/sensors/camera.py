"""RGB and depth cameras by ray casting the same world as the LiDAR (``sensor_msgs/Image`` + ``CameraInfo``).

Why ray casting: measured on our 2-core machines (``benchmarks/test_bench_camera.py``,
both in the same run), casting one ray per pixel through Open3D's RaycastingScene is faster than PyBullet's
TinyRenderer (about 2.5x at 640x480), needs no GPU or EGL, and gives depth and colour from the very
same hits, so RGB and depth of one camera agree geometrically by construction.

Pinhole model in the optical frame (REP-103: z forward, x right, y down), square pixels:
``fx = fy = (width / 2) / tan(hfov / 2)``, principal point at the image centre ``((w-1)/2, (h-1)/2)``
(pixel centres at integer coordinates, as in OpenCV and ROS), no distortion. The ray through pixel
``(u, v)`` is ``((u - cx) / fx, (v - cy) / fy, 1)``.

- Depth (``32FC1``): the z coordinate of the hit in the optical frame, in metres (REP-118), ``+inf``
  where nothing is hit within ``max_range_m``.
- RGB (``rgb8``): flat colours per scene class (and each vehicle's own colour) lit by a sun
  (ambient + Lambert), sky colour where nothing is hit. A look for perception tests, not photorealism.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Annotated, Any, ClassVar

import esper
import numpy as np

from ..components.body import Appearance, FleetSlot
from ..config.limits import MAX_XY_M, SensorRate
from ..config.schema import Gt, Le, Lt
from ..control.compiled import jit
from ..phases import Phase
from ..scene.colors import class_rgb
from ..world import StepContext
from .base import MountedSensor, SensorSpec
from .raycast_system import RaycastSensorSystem
from .messages import header, msg_type
from .raycast import MOVING_BODY, NO_HIT

# optical frame axes in the camera link (FLU): optical x = -link y, optical y = -link z, optical z = link x
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
SKY_RGB = np.array([0.62, 0.76, 0.92])
SUN_DIR_ENU = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
AMBIENT = 0.45


@dataclass(frozen=True, kw_only=True)
class CameraSpec(SensorSpec):
    """Shared camera fields."""

    rate_hz: SensorRate = 10.0                 # [Hz], config.limits
    # 1920 x 1200 (WUXGA, a common machine-vision format) at most: every pixel is a ray cast each
    # frame (measured on 2 cores: a 1920 x 1200 camera peaks at 0.9 GB and ~10 s a frame; two
    # 4096 x 3072 cameras at 4.4 GB and 60 s a frame; 20000 x 20000 would need tens of GB)
    width: Annotated[int, Gt(0), Le(1920)] = 640
    height: Annotated[int, Gt(0), Le(1200)] = 480
    hfov_deg: Annotated[float, Gt(0.0), Lt(180.0)] = 90.0
    max_range_m: Annotated[float, Gt(0.0), Le(2.0 * MAX_XY_M)] = 200.0   # across the whole world at most


@dataclass(frozen=True, kw_only=True)
class RgbCamera(CameraSpec):
    """World-file key ``camera``: ``rgb8`` images on ``/<vehicle>/camera/image_raw``."""

    LINK: ClassVar[str] = "camera_link"
    OPTICAL: ClassVar[str] = "camera_optical_frame"


@dataclass(frozen=True, kw_only=True)
class DepthCamera(CameraSpec):
    """World-file key ``depth_camera``: ``32FC1`` metres on ``/<vehicle>/depth/image_raw``."""

    LINK: ClassVar[str] = "depth_link"
    OPTICAL: ClassVar[str] = "depth_optical_frame"


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """Camera matrix K (3, 3) for square pixels and a centred principal point."""
    f = (width / 2.0) / np.tan(np.deg2rad(hfov_deg) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def pixel_rays_optical(width: int, height: int, hfov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit ray directions (H*W, 3) in the optical frame, row-major, and their z components (H*W,)."""
    K = intrinsics(width, height, hfov_deg)
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d, d[:, 2].copy()


def camera_info(time_s: float, frame_id: str, width: int, height: int, hfov_deg: float) -> Any:
    K = intrinsics(width, height, hfov_deg)
    P = np.hstack([K, np.zeros((3, 1))])
    return msg_type("sensor_msgs/msg/CameraInfo")(
        header=header(time_s, frame_id), height=height, width=width, distortion_model="plumb_bob",
        d=np.zeros(5), k=K.reshape(-1).copy(), r=np.eye(3).reshape(-1).copy(), p=P.reshape(-1).copy(),
        binning_x=0, binning_y=0,
        roi=msg_type("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def image(time_s: float, frame_id: str, width: int, height: int, encoding: str, pixels: np.ndarray) -> Any:
    data = np.ascontiguousarray(pixels)
    return msg_type("sensor_msgs/msg/Image")(
        header=header(time_s, frame_id), height=height, width=width, encoding=encoding, is_bigendian=0,
        step=data.nbytes // height, data=np.frombuffer(data.tobytes(), dtype=np.uint8))


def read_image(msg: Any) -> np.ndarray:
    """Pixels of an ``rgb8`` (H, W, 3) uint8 or ``32FC1`` (H, W) float32 Image."""
    raw = np.asarray(msg.data, dtype=np.uint8).tobytes()
    if msg.encoding == "rgb8":
        return np.frombuffer(raw, dtype=np.uint8).reshape(msg.height, msg.width, 3)
    if msg.encoding == "32FC1":
        return np.frombuffer(raw, dtype="<f4").reshape(msg.height, msg.width)
    raise ValueError(f"unsupported encoding {msg.encoding!r}")


def view_key(s: MountedSensor) -> tuple[Any, ...]:
    """What fixes a camera's rays and their hits: its vehicle, mount, image size, field of view and range."""
    spec = s.spec
    return (s.entity, tuple(spec.mount_xyz_m), tuple(spec.mount_rpy_deg), spec.width, spec.height, spec.hfov_deg,
            spec.max_range_m)


class _CameraSystem(RaycastSensorSystem):
    """One ray per pixel for every camera of this kind that is due (cast in one batch)."""

    def __init__(self) -> None:
        super().__init__()
        self._rays: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}   # entity -> dirs (link), z, exit

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        self._rays = {}
        for s in self.sensors:
            d_opt, z = pixel_rays_optical(s.spec.width, s.spec.height, s.spec.hfov_deg)
            d_link = d_opt @ R_LINK_OPTICAL.T
            self._rays[s.entity] = (d_link, z, self.own_exit_m(s, d_link))
        self._colours = self._body_colours(ctx)

    def _body_colours(self, ctx: StepContext) -> np.ndarray:
        """RGB (N, 3) of every moving body, in the order of the moving boxes."""
        by_row = {slot.row: np.asarray(look.rgba[:3], dtype=float)
                  for _, (slot, look) in esper.get_components(FleetSlot, Appearance)}
        return np.array([by_row.get(int(r), np.full(3, 0.5)) for r in self._body_rows]).reshape(-1, 3)

    def cast_frames(self, ctx: StepContext, due: list[MountedSensor], time_s: float
                    ) -> list[tuple[Any, slice, np.ndarray]]:
        """Cast every due camera in one batch; per camera: (hits, its slice of them, its world directions).

        A camera whose view another camera of its vehicle cast this very step (an RGB and a depth camera
        with the same mount, size, field of view and range: an RGB-D camera) takes that cast's hits, so
        its colour and depth come from one cast and agree pixel for pixel."""
        shared = ctx.services.camera_casts
        if shared.get("time_s") != time_s:
            shared.clear()
            shared["time_s"] = time_s
        views = [view_key(s) for s in due]
        todo = [k for k, view in enumerate(views) if view not in shared]
        if todo:
            hits, cast, plan = self.cast_due(ctx, [due[k] for k in todo],
                                             [(self._rays[due[k].entity][0], self._rays[due[k].entity][2])
                                              for k in todo])
            for k, sl in zip(todo, plan.slices):
                shared[views[k]] = (hits, sl, cast[sl, 3:])
        return [shared[view] for view in views]

    def publish_info(self, ctx: StepContext, s: MountedSensor, time_s: float) -> None:
        """The CameraInfo of a frame, on ``<image topic's namespace>/camera_info`` (image_transport)."""
        topic = s.topic.rsplit("/", 1)[0] + "/camera_info"
        self.publish(ctx, s, time_s, key=f"{self.key}_info", topic=topic,
                     build=partial(camera_info, time_s, s.frame_id, s.spec.width, s.spec.height, s.spec.hfov_deg))


_CLASS_RGB = class_rgb()


class RgbCameraSystem(_CameraSystem):
    """Every RGB camera that is due. Phase: SENSORS."""

    phase = Phase.SENSORS
    order = 60
    spec_type = RgbCamera
    key = "camera"
    topic_suffix = "camera/image_raw"

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        for s, (hits, sl, dirs_w) in zip(due, self.cast_frames(ctx, due, time_s)):
            spec: RgbCamera = s.spec
            pixels = np.empty((spec.height, spec.width, 3), dtype=np.uint8)
            shade_pixels(hits.cls[sl], hits.box[sl], hits.normal[sl], dirs_w, hits.t[sl], spec.max_range_m,
                         _CLASS_RGB, self._colours, pixels.reshape(-1, 3))
            self.publish(ctx, s, time_s,
                         build=partial(image, time_s, s.frame_id, spec.width, spec.height, "rgb8", pixels))
            self.publish_info(ctx, s, time_s)


@jit
def shade_pixels(cls, box, normal, dirs_w, t, max_range_m, class_rgb_table, body_rgb, pixels):
    """RGB8 ``pixels`` (M, 3) of M rays' hits: the colour of the class hit (of the body, for a moving body),
    lit by the sun (Lambert on the normal turned to face the camera, plus ambient); sky where the ray hit
    nothing within ``max_range_m``. ``cls`` (M,), ``box`` (M,), ``normal`` and ``dirs_w`` (M, 3), ``t`` (M,)."""
    for k in range(cls.shape[0]):
        c = cls[k]
        if c == NO_HIT or not t[k] <= max_range_m:
            for i in range(3):
                pixels[k, i] = np.uint8(min(255.0, max(0.0, SKY_RGB[i] * 255.0 + 0.5)))
            continue
        n0, n1, n2 = np.float64(normal[k, 0]), np.float64(normal[k, 1]), np.float64(normal[k, 2])
        if normal[k, 0] * dirs_w[k, 0] + normal[k, 1] * dirs_w[k, 1] + normal[k, 2] * dirs_w[k, 2] > 0:
            n0, n1, n2 = -n0, -n1, -n2                     # turned to face the camera
        lambert = n0 * SUN_DIR_ENU[0] + n1 * SUN_DIR_ENU[1] + n2 * SUN_DIR_ENU[2]
        shade = AMBIENT + (1.0 - AMBIENT) * min(1.0, max(0.0, lambert))
        for i in range(3):
            colour = body_rgb[box[k], i] if c == MOVING_BODY else class_rgb_table[min(255, max(0, c)), i]
            pixels[k, i] = np.uint8(min(255.0, max(0.0, colour * shade * 255.0 + 0.5)))


class DepthCameraSystem(_CameraSystem):
    """Every depth camera that is due. Phase: SENSORS."""

    phase = Phase.SENSORS
    order = 61
    spec_type = DepthCamera
    key = "depth_camera"
    topic_suffix = "depth/image_raw"

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        for s, (hits, sl, _) in zip(due, self.cast_frames(ctx, due, time_s)):
            spec: DepthCamera = s.spec
            _, z, _ = self._rays[s.entity]
            t = hits.t[sl]
            depth = np.where(t <= spec.max_range_m, t * z, np.inf).astype("<f4").reshape(spec.height, spec.width)
            self.publish(ctx, s, time_s,
                         build=partial(image, time_s, s.frame_id, spec.width, spec.height, "32FC1", depth))
            self.publish_info(ctx, s, time_s)


__all__ = ["DepthCamera", "DepthCameraSystem", "RgbCamera", "RgbCameraSystem", "camera_info",
           "intrinsics", "pixel_rays_optical", "read_image"]
