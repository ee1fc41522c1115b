"""Odometry: ground-truth ``nav_msgs/Odometry`` of the vehicle body.

Pose of ``<vehicle>/base_link`` in ``<vehicle>/odom`` (REP-105), where the odom frame coincides with
the world ENU frame (``map``): ground truth does not drift. Twist in the child frame
(``base_link``, FLU): linear ``R^T v``, angular the body rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from ..config.limits import SensorRate
from ..phases import Phase
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import header, msg_type, point, quaternion, vector3

GROUND_TRUTH_VARIANCE = 1e-6


@dataclass(frozen=True, kw_only=True)
class OdometrySensor(SensorSpec):
    """World-file key ``odometry``."""

    rate_hz: SensorRate = 50.0                 # [Hz], config.limits


class OdometrySystem(SensorSystemBase):
    """Every odometry output that is due. Phase: SENSORS."""

    phase = Phase.SENSORS
    order = 40
    spec_type = OdometrySensor
    key = "odometry"
    topic_suffix = "odom"
    link = "odom"

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        f = ctx.fleet
        rows = np.array([s.row for s in due])
        pos, quat, rate = f.pos_enu_m[rows], f.quat_enu_flu_xyzw[rows], f.rate_flu_rad_s[rows]     # copies
        v_body = np.einsum("nji,nj->ni", f.R_enu_flu[rows], f.vel_enu_m_s[rows])
        for k, s in enumerate(due):
            self.publish(ctx, s, time_s, build=partial(odometry_message, time_s, s.frame_id, f"{s.vehicle}/base_link",
                                                       pos[k], quat[k], v_body[k], rate[k]))


def odometry_message(time_s: float, frame_id: str, child_frame_id: str, pos_enu_m: np.ndarray, quat_xyzw: np.ndarray,
                     vel_flu_m_s: np.ndarray, rate_flu_rad_s: np.ndarray) -> Any:
    """The nav_msgs/Odometry of one ground-truth sample (pose in odom, twist in base_link)."""
    cov = np.eye(6).reshape(-1) * GROUND_TRUTH_VARIANCE
    Odometry = msg_type("nav_msgs/msg/Odometry")
    PoseCov, TwistCov = msg_type("geometry_msgs/msg/PoseWithCovariance"), msg_type("geometry_msgs/msg/TwistWithCovariance")
    Pose, Twist = msg_type("geometry_msgs/msg/Pose"), msg_type("geometry_msgs/msg/Twist")
    return Odometry(header=header(time_s, frame_id), child_frame_id=child_frame_id,
                    pose=PoseCov(pose=Pose(position=point(pos_enu_m), orientation=quaternion(quat_xyzw)),
                                 covariance=cov.copy()),
                    twist=TwistCov(twist=Twist(linear=vector3(vel_flu_m_s), angular=vector3(rate_flu_rad_s)),
                                   covariance=cov.copy()))


__all__ = ["OdometrySensor", "OdometrySystem", "odometry_message"]
