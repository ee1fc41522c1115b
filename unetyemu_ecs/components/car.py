"""Ground-vehicle components (world-file keys ``car_dynamics`` and ``route``); parameters only.

Defaults per preset live in ``vehicles/params/car.toml``; every field can be overridden per vehicle.
Body frame FLU; lengths in metres, torques in N m per wheel unless said otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np

from ..config.limits import MAX_WAYPOINTS, XM
from ..config.schema import FieldError, Ge, Gt, Le, Lt, MaxLen, NonEmpty


@dataclass(frozen=True, slots=True, kw_only=True)
class CarDynamics:
    """Chassis, wheels, suspension, drive and brakes of a car (world-file key ``car_dynamics``)."""

    # Ranges: road vehicles up to a mining truck (wheelbase 20 m, track 5 m, 2 m wheels of 1 t);
    # torques within 100 kN m; 100 m/s is beyond any road car's top speed; a steering rack slews a few
    # hundred deg/s; springs within 10 MN/m, dampers 1 MN s/m, travel 1 m; tyres grip below ~2 (slicks)
    wheelbase_m: Annotated[float, Gt(0.0), Le(20.0)]
    track_m: Annotated[float, Gt(0.0), Le(5.0)]
    wheel_radius_m: Annotated[float, Gt(0.0), Le(2.0)]
    wheel_width_m: Annotated[float, Gt(0.0), Le(2.0)]
    wheel_mass_kg: Annotated[float, Gt(0.0), Le(1_000.0)]
    max_drive_torque_n_m: Annotated[float, Gt(0.0), Le(1e5)]      # total at the rear axle, shared by the two wheels
    max_brake_torque_n_m: Annotated[float, Gt(0.0), Le(1e5)]      # per wheel
    rolling_resistance_coeff: Annotated[float, Ge(0.0), Lt(1.0)]   # C_rr: drag torque C_rr m g r / 4 per wheel
    top_speed_m_s: Annotated[float, Gt(0.0), Le(100.0)]
    max_steer_deg: Annotated[float, Gt(0.0), Lt(60.0)]
    steer_scale_at_50_m_s: Annotated[float, Gt(0.0), Le(1.0)]     # steering limit scale at 50 m/s
    max_steer_rate_deg_s: Annotated[float, Gt(0.0), Le(1_000.0)]  # steering actuator slew rate (front wheels)
    suspension_stiffness_n_m: Annotated[float, Gt(0.0), Le(1e7)]  # per wheel [N/m]
    suspension_damping_n_s_m: Annotated[float, Ge(0.0), Le(1e6)]  # per wheel [N s/m]
    suspension_travel_m: Annotated[float, Gt(0.0), Le(1.0)]       # +/- from the static rest position
    tyre_friction: Annotated[float, Gt(0.0), Le(5.0)]             # times the surface's (road 0.9)

    def __post_init__(self) -> None:
        if np.any(np.asarray(self.wheel_width_m) >= np.asarray(self.track_m)):   # arrays when stacked per fleet
            raise FieldError("wheel_width_m", f"wheels {self.wheel_width_m} m wide do not fit a "
                                              f"{self.track_m} m track")


@dataclass(frozen=True, slots=True, kw_only=True)
class RouteWaypoint:
    """A point of a car route, ENU metres on the ground."""

    x: XM       # within the world's extent (config.limits.MAX_XY_M)
    y: XM


@dataclass(frozen=True, slots=True, kw_only=True)
class CarRoute:
    """A route the car drives from t = 0 (world-file key ``route``): through the waypoints in order,
    at ``speed_m_s`` (slower in corners), stopping at the last one or, with ``loop``, going round
    for ``laps`` laps (0 = forever)."""

    waypoints: Annotated[list[RouteWaypoint], NonEmpty(), MaxLen(MAX_WAYPOINTS)]
    speed_m_s: Annotated[float, Gt(0.0), Le(40.0)] | None = None     # None: the controller's cruise speed
    loop: bool = False
    laps: Annotated[int, Ge(0), Le(10_000)] = 0   # 10 000 laps of even a 100 m block take 12 days at 1 m/s

    def __post_init__(self) -> None:
        if self.loop and len(self.waypoints) < 3:
            raise FieldError("waypoints", f"a loop needs at least 3 waypoints, got {len(self.waypoints)}")
        if self.laps and not self.loop:
            raise FieldError("laps", "laps applies to a loop (set loop: true)")
        for i in range(1, len(self.waypoints)):
            a, b = self.waypoints[i - 1], self.waypoints[i]
            if abs(a.x - b.x) < 1e-6 and abs(a.y - b.y) < 1e-6:
                raise FieldError("waypoints", f"waypoints {i - 1} and {i} are the same point ({a.x}, {a.y})")


@dataclass(frozen=True, slots=True, kw_only=True)
class CarBody:
    """The joints of a car's PyBullet multibody (a :class:`~unetyemu_ecs.physics.car_body.CarJoints`)."""

    joints: Any


__all__ = ["CarBody", "CarDynamics", "CarRoute", "RouteWaypoint"]
