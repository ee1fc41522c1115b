"""Quadrotor components: motors, guidance limits, payload bay, energy, scripted teleop.

Every field is required: values come from the preset files (``vehicles/params/quadrotor.toml``,
which cite their sources) merged with the world file's ``components:`` overrides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from ..config.limits import MAX_DURATION_S, MAX_KEYFRAMES
from ..config.schema import Each, FieldError, Ge, Gt, Le, Lt, MaxLen


@dataclass(frozen=True, slots=True, kw_only=True)
class QuadrotorMotors:
    """Four motors in X configuration (FL, FR, BR, BL), body frame FLU (world-file key ``motors``)."""

    # Ranges: 10 kN is a passenger eVTOL rotor; 10 m arms; reaction torque / thrust is ~0.01-0.02 m;
    # motors spin up in tens of ms (1 s is a sluggish heavy lifter)
    max_thrust_per_motor_n: Annotated[float, Gt(0.0), Le(10_000.0)]   # F_max per motor [N]
    arm_length_m: Annotated[float, Gt(0.0), Le(10.0)]                 # centre of mass -> motor axis [m]
    yaw_moment_coeff_m: Annotated[float, Ge(0.0), Le(1.0)]            # rotor reaction torque / thrust [m]
    motor_tau_s: Annotated[float, Ge(0.0), Le(1.0)]                   # first-order spin-up time constant, 0 = none [s]


@dataclass(frozen=True, slots=True, kw_only=True)
class GuidanceLimits:
    """Layer-3 limits and pure-pursuit parameters (world-file key ``guidance``)."""

    # Ranges: racing drones reach ~50 m/s vertically and ~100 m/s level (the caps); 1000 deg/s of yaw is
    # acro flight; distances within 1 km; heights within the world's 10 km (config.limits.MAX_Z_M)
    max_tilt_deg: Annotated[float, Gt(0.0), Lt(90.0)]
    lim_climb_m_s: Annotated[float, Gt(0.0), Le(50.0)]
    lim_descent_m_s: Annotated[float, Gt(0.0), Le(50.0)]
    lim_yaw_rate_deg_s: Annotated[float, Gt(0.0), Le(1_000.0)]
    lead_distance_m: Annotated[float, Gt(0.0), Le(1_000.0)]
    final_approach_m: Annotated[float, Gt(0.0), Le(1_000.0)]
    arrival_radius_m: Annotated[float, Gt(0.0), Le(100.0)]
    cruise_speed_m_s: Annotated[float, Gt(0.0), Le(100.0)]   # default speeds when a target/waypoint gives none
    climb_speed_m_s: Annotated[float, Gt(0.0), Le(50.0)]
    descent_speed_m_s: Annotated[float, Gt(0.0), Le(50.0)]
    takeoff_altitude_m: Annotated[float, Gt(0.0), Le(10_000.0)]   # above the take-off surface, when a step gives none

    def __post_init__(self) -> None:
        if self.climb_speed_m_s > self.lim_climb_m_s:
            raise FieldError("climb_speed_m_s", f"default climb speed {self.climb_speed_m_s:g} m/s exceeds "
                                                f"lim_climb_m_s {self.lim_climb_m_s:g}")
        if self.descent_speed_m_s > self.lim_descent_m_s:
            raise FieldError("descent_speed_m_s", f"default descent speed {self.descent_speed_m_s:g} m/s exceeds "
                                                  f"lim_descent_m_s {self.lim_descent_m_s:g}")


@dataclass(frozen=True, slots=True, kw_only=True)
class PayloadBay:
    """What the drone can grab (world-file key ``payload``)."""

    # Ranges: heavy-lift drones carry up to ~200 kg (1 t is a cargo eVTOL); a grab reaches within 10 m
    max_payload_kg: Annotated[float, Ge(0.0), Le(1_000.0)]
    reach_horizontal_m: Annotated[float, Gt(0.0), Le(10.0)]
    reach_vertical_m: Annotated[float, Gt(0.0), Le(10.0)]


@dataclass(frozen=True, slots=True, kw_only=True)
class EnergyModel:
    """Actuator-disk power model and battery (world-file key ``energy``).

    ``P_i = F_i^1.5 / (sqrt(2 rho A) eta)`` with ``A = pi r^2``; ``P = sum P_i + p0_w``.
    """

    # Ranges: rotors within 10 m radius; air as in AeroDrag; avionics within 100 kW; packs up to 1 MWh
    # and chargers up to 1 MW (megawatt truck charging); the power filter within an hour
    rotor_radius_m: Annotated[float, Gt(0.0), Le(10.0)]
    efficiency: Annotated[float, Gt(0.0), Le(1.0)]
    air_density_kg_m3: Annotated[float, Ge(0.01), Le(2.0)]
    p0_w: Annotated[float, Ge(0.0), Le(1e5)]                      # avionics, always drawn
    battery_wh: Annotated[float, Gt(0.0), Le(1e6)]
    initial_soc_frac: Annotated[float, Ge(0.0), Le(1.0)]
    charge_power_w: Annotated[float, Gt(0.0), Le(1e6)]            # charger power on a pad (recharge step)
    low_battery_land_frac: Annotated[float, Ge(0.0), Lt(1.0)]   # abort the mission and land below this
    remaining_time_tau_s: Annotated[float, Gt(0.0), Le(3_600.0)]  # filter on power for remaining flight time


@dataclass(frozen=True, slots=True, kw_only=True)
class TeleopKeyframe:
    """Stick input ``[throttle, pitch, roll, yaw]`` in [-1, 1] held from ``t_s`` on."""

    t_s: Annotated[float, Ge(0.0), Le(MAX_DURATION_S)]   # within the longest run (a week)
    stick: Annotated[tuple[float, float, float, float], Each(Ge(-1.0)), Each(Le(1.0))]


@dataclass(frozen=True, slots=True, kw_only=True)
class TeleopScript:
    """Scripted teleop: the drone flies in manual mode on these sticks (world-file key ``teleop_script``)."""

    keyframes: Annotated[list[TeleopKeyframe], MaxLen(MAX_KEYFRAMES)]

    def __post_init__(self) -> None:
        times = [k.t_s for k in self.keyframes]
        if not times:
            raise FieldError("keyframes", "needs at least one keyframe")
        if times != sorted(times):
            raise FieldError("keyframes", f"keyframe times must increase, got {times}")
