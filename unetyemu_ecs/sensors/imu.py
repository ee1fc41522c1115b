"""IMU: body angular velocity, specific force and orientation, as ``sensor_msgs/Imu``.

Measured at the sensor frame's origin from the body's motion over the last physics step:

- angular velocity ``w_s = R_bs^T w_b`` (body rates, FLU, rotated into the sensor axes);
- specific force ``f_s = R_ws^T (a - g)``: what an accelerometer feels, so a vehicle at rest reads
  ``+9.81 m/s^2`` up and one in free fall reads zero. ``a`` is the body's acceleration over the
  last step (velocity difference); the lever-arm terms of a mount away from the centre of mass
  (``w x (w x r) + dw/dt x r``) are not modelled;
- orientation of the sensor frame in ENU (REP-103/145).

Noise (all off by default): white noise of the given standard deviation on every sample, plus a
bias that follows a random walk (``sigma_bw sqrt(dt)`` per sample); the covariances carry the
white-noise variances. Each IMU has its own seeded stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Annotated, Any, ClassVar

import numpy as np

from ..config.limits import SensorRate
from ..config.schema import Ge, Le
from ..frames import R_from_quat_xyzw, quat_multiply_xyzw
from ..phases import Phase
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import diagonal_covariance, header, msg_type, quaternion, vector3

ORIENTATION_VARIANCE_RAD2 = 1e-6     # ground-truth orientation: tiny, but known (not -1 "unavailable")


@dataclass(frozen=True, kw_only=True)
class ImuSensor(SensorSpec):
    """World-file key ``imu``."""

    LINK: ClassVar[str] = "imu_link"

    rate_hz: SensorRate = 100.0                 # [Hz], config.limits
    # Ranges: MEMS gyros are ~0.001-0.01 rad/s and accelerometers ~0.01-0.1 m/s^2 per sample; noise
    # of 10 rad/s or 100 m/s^2 (10 g) or bias walks of 1 unit per sqrt(s) already drown every signal
    gyro_noise_std_rad_s: Annotated[float, Ge(0.0), Le(10.0)] = 0.0
    accel_noise_std_m_s2: Annotated[float, Ge(0.0), Le(100.0)] = 0.0
    gyro_bias_walk_rad_s2: Annotated[float, Ge(0.0), Le(1.0)] = 0.0     # bias random walk [rad/s per sqrt(s)]
    accel_bias_walk_m_s3: Annotated[float, Ge(0.0), Le(10.0)] = 0.0     # [m/s^2 per sqrt(s)]


class ImuSystem(SensorSystemBase):
    """Every IMU that is due, in one pass. Phase: SENSORS. Reads: fleet pose, rates, acceleration."""

    phase = Phase.SENSORS
    order = 10
    spec_type = ImuSensor
    key = "imu"
    topic_suffix = "imu/data"

    def __init__(self) -> None:
        super().__init__()
        self._bias: dict[int, np.ndarray] = {}           # entity -> (6,) gyro, accel bias
        self._last_s: dict[int, float] = {}

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        f = ctx.fleet
        rows = np.array([s.row for s in due])
        q_mount = np.array([s.spec.mount_quat_xyzw() for s in due])
        R_mount = R_from_quat_xyzw(q_mount)                                    # sensor axes in body
        R_body = f.R_enu_flu[rows]                                             # body in ENU
        specific_enu = f.acc_enu_m_s2[rows] - np.asarray(ctx.services.gravity_enu_m_s2)
        specific_body = np.einsum("nji,nj->ni", R_body, specific_enu)           # R_body^T f
        accel = np.einsum("nji,nj->ni", R_mount, specific_body)
        gyro = np.einsum("nji,nj->ni", R_mount, f.rate_flu_rad_s[rows])
        q_sensor = quat_multiply_xyzw(f.quat_enu_flu_xyzw[rows], q_mount)
        for k, s in enumerate(due):
            spec: ImuSensor = s.spec
            g, a = gyro[k].copy(), accel[k].copy()
            if spec.gyro_noise_std_rad_s or spec.accel_noise_std_m_s2 or spec.gyro_bias_walk_rad_s2 \
                    or spec.accel_bias_walk_m_s3:
                rng = self.rng_for(ctx, s)
                bias = self._bias.setdefault(s.entity, np.zeros(6))
                dt = time_s - self._last_s.get(s.entity, time_s)
                walk = np.sqrt(max(dt, 0.0)) * np.r_[np.full(3, spec.gyro_bias_walk_rad_s2),
                                                      np.full(3, spec.accel_bias_walk_m_s3)]
                bias += walk * rng.standard_normal(6)
                white = np.r_[np.full(3, spec.gyro_noise_std_rad_s), np.full(3, spec.accel_noise_std_m_s2)]
                noise = bias + white * rng.standard_normal(6)
                g += noise[:3]
                a += noise[3:]
            self._last_s[s.entity] = time_s
            self.publish(ctx, s, time_s, build=partial(imu_message, time_s, s.frame_id, q_sensor[k], g, a,
                                                       spec.gyro_noise_std_rad_s ** 2, spec.accel_noise_std_m_s2 ** 2))


def imu_message(time_s: float, frame_id: str, q_xyzw: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray,
                gyro_var: float, accel_var: float) -> Any:
    """The sensor_msgs/Imu of one measurement (orientation xyzw in ENU, body rates and specific force in the
    sensor axes, diagonal covariances)."""
    return msg_type("sensor_msgs/msg/Imu")(
        header=header(time_s, frame_id), orientation=quaternion(q_xyzw),
        orientation_covariance=diagonal_covariance([ORIENTATION_VARIANCE_RAD2] * 3),
        angular_velocity=vector3(gyro_rad_s), angular_velocity_covariance=diagonal_covariance([gyro_var] * 3),
        linear_acceleration=vector3(accel_m_s2), linear_acceleration_covariance=diagonal_covariance([accel_var] * 3))


__all__ = ["ImuSensor", "ImuSystem", "imu_message"]
