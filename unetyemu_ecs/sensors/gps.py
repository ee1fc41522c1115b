"""GPS: ``sensor_msgs/NavSatFix`` from the antenna's ENU position by a proper ENU -> WGS84 conversion.

The antenna sits at the sensor mount; its ENU position goes through the world's local tangent plane
(:class:`~unetyemu_ecs.geodesy.LocalTangentPlane`, via ECEF) to latitude, longitude and ellipsoidal
altitude. Optional Gaussian noise in metres (horizontal east/north, vertical), seeded per receiver;
the covariance is diagonal and known (its variances are the noise's).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Annotated, Any, ClassVar

import numpy as np

from ..config.limits import SensorRate
from ..config.schema import Ge, Le
from ..geodesy import LocalTangentPlane
from ..phases import Phase
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import header, msg_type

GROUND_TRUTH_VARIANCE_M2 = 1e-4      # a noiseless receiver still reports a (tiny) known covariance


@dataclass(frozen=True, kw_only=True)
class GpsSensor(SensorSpec):
    """World-file key ``gps``."""

    LINK: ClassVar[str] = "gps_link"

    rate_hz: SensorRate = 10.0                 # [Hz], config.limits
    # noise within 100 m: a GPS worse than that is no fix (consumer receivers are ~2-5 m)
    horizontal_noise_std_m: Annotated[float, Ge(0.0), Le(100.0)] = 0.0
    vertical_noise_std_m: Annotated[float, Ge(0.0), Le(100.0)] = 0.0


class GpsSystem(SensorSystemBase):
    """Every GPS receiver that is due, in one pass. Phase: SENSORS."""

    phase = Phase.SENSORS
    order = 20
    spec_type = GpsSensor
    key = "gps"
    topic_suffix = "gps/fix"

    def __init__(self) -> None:
        super().__init__()
        self._ltp: LocalTangentPlane | None = None

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        if self._ltp is None:
            self._ltp = LocalTangentPlane(ctx.services.origin)
        f = ctx.fleet
        rows = np.array([s.row for s in due])
        mounts = np.array([s.spec.mount_xyz_m for s in due], dtype=float)
        antenna = f.pos_enu_m[rows] + np.einsum("nij,nj->ni", f.R_enu_flu[rows], mounts)
        for k, s in enumerate(due):
            spec: GpsSensor = s.spec
            if spec.horizontal_noise_std_m or spec.vertical_noise_std_m:
                std = np.array([spec.horizontal_noise_std_m, spec.horizontal_noise_std_m, spec.vertical_noise_std_m])
                antenna[k] += std * self.rng_for(ctx, s).standard_normal(3)
        lat, lon, alt = self._ltp.to_geodetic(antenna)
        for k, s in enumerate(due):
            spec = s.spec
            var_h = max(spec.horizontal_noise_std_m ** 2, GROUND_TRUTH_VARIANCE_M2)
            var_v = max(spec.vertical_noise_std_m ** 2, GROUND_TRUTH_VARIANCE_M2)
            self.publish(ctx, s, time_s, build=partial(fix_message, time_s, s.frame_id, float(lat[k]), float(lon[k]),
                                                       float(alt[k]), var_h, var_v))


def fix_message(time_s: float, frame_id: str, lat_deg: float, lon_deg: float, alt_m: float, var_h_m2: float,
                var_v_m2: float) -> Any:
    """The sensor_msgs/NavSatFix of one fix (WGS84 degrees, ellipsoid height, diagonal covariance)."""
    NavSatFix, NavSatStatus = msg_type("sensor_msgs/msg/NavSatFix"), msg_type("sensor_msgs/msg/NavSatStatus")
    return NavSatFix(header=header(time_s, frame_id),
                     status=NavSatStatus(status=NavSatStatus.STATUS_FIX, service=NavSatStatus.SERVICE_GPS),
                     latitude=lat_deg, longitude=lon_deg, altitude=alt_m,
                     position_covariance=np.diag([var_h_m2, var_h_m2, var_v_m2]).reshape(-1).astype(np.float64),
                     position_covariance_type=NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)


__all__ = ["GpsSensor", "GpsSystem", "fix_message"]
