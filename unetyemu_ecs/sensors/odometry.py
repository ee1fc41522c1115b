"""Odometry: ground-truth ``nav_msgs/Odometry`` of the vehicle body.

Pose of ``<vehicle>/base_link`` in ``<vehicle>/odom`` (REP-105), where the odom frame coincides with
the world ENU frame (``map``): ground truth does not drift. Twist in the child frame
(``base_link``, FLU): linear ``R^T v``, angular the body rates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config.limits import SensorRate
from ..frames import R_from_quat_xyzw
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
        R = R_from_quat_xyzw(f.quat_enu_flu_xyzw[rows])
        v_body = np.einsum("nji,nj->ni", R, f.vel_enu_m_s[rows])
        cov = np.eye(6).reshape(-1) * GROUND_TRUTH_VARIANCE
        Odometry = msg_type("nav_msgs/msg/Odometry")
        PoseCov, TwistCov = msg_type("geometry_msgs/msg/PoseWithCovariance"), msg_type("geometry_msgs/msg/TwistWithCovariance")
        Pose, Twist = msg_type("geometry_msgs/msg/Pose"), msg_type("geometry_msgs/msg/Twist")
        for k, s in enumerate(due):
            r = rows[k]
            msg = Odometry(header=header(time_s, s.frame_id), child_frame_id=f"{s.vehicle}/base_link",
                           pose=PoseCov(pose=Pose(position=point(f.pos_enu_m[r]),
                                                  orientation=quaternion(f.quat_enu_flu_xyzw[r])), covariance=cov.copy()),
                           twist=TwistCov(twist=Twist(linear=vector3(v_body[k]), angular=vector3(f.rate_flu_rad_s[r])),
                                          covariance=cov.copy()))
            self.publish(ctx, s, time_s, msg)


__all__ = ["OdometrySensor", "OdometrySystem"]
