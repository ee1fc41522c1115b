"""Quadrotor components: motors, guidance limits, payload bay, energy, scripted teleop.

Every field is required: values come from the preset files (``vehicles/params/quadrotor.toml``,
which cite their sources) merged with the world file's ``components:`` overrides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

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
    # more thrust per command near a surface below (Cheeseman & Bennett 1955: x1/(1 - (R/4z)^2), capped at
    # 4/3, none above 4 R; R from ``energy.rotor_radius_m``, no ``energy``: none); control.ground_effect.
    # Off by default: armed on the ground, the stack holds position with hover thrust, which the
    # ground effect turns into a lift-off (tests/integration/test_ground_effect.py)
    ground_effect: bool = False
    # the pack voltage at which max_thrust_per_motor_n is rated: given, each motor's maximum thrust follows
    # the battery, (V_pack / rated_voltage_v)^2 (a motor's top speed is K_v V and thrust goes as speed^2),
    # so a sagging or emptying pack lifts less; none: a fixed maximum. Range: up to an eVTOL's 1 kV pack
    # (a 6S drone pack is 22.2 V nominal)
    rated_voltage_v: Annotated[float, Gt(0.0), Le(1_000.0)] | None = None


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


LIPO_CELL_NOMINAL_V = 3.7     # [V]


@dataclass(frozen=True, slots=True, kw_only=True)
class EnergyModel:
    """Rotor power and battery of a drone (world-file key ``energy``).

    ``model``: ``momentum`` (default) is momentum theory with the real inflow through each rotor --
    climb, descent (vortex-ring state) and forward flight (Glauert) -- plus the growth of blade
    profile power with advance ratio (:mod:`unetyemu_ecs.control.rotor_power`); in hover it is
    exactly the paper's eq. 4. ``hover_actuator_disk`` is eq. 4 applied to the thrust alone,
    ``P_i = F_i^1.5 / (sqrt(2 rho A) eta)``, whatever the drone's motion (the paper's model).
    ``P = sum P_i + p0_w``.

    ``battery``: ``lipo`` (default) is an equivalent-circuit LiPo pack
    (:mod:`unetyemu_ecs.control.battery_ecm`: open-circuit voltage vs state of charge, R0, one RC
    pair, cut-off voltage, capacity fade with cycles) of ``battery_wh`` at ``cells_series`` x 3.7 V;
    ``ideal`` is the paper's energy bucket at a constant voltage.
    """

    # Ranges: rotors within 10 m radius; air as in AeroDrag; avionics within 100 kW; packs up to 1 MWh
    # and chargers up to 1 MW (megawatt truck charging); the power filter within an hour
    rotor_radius_m: Annotated[float, Gt(0.0), Le(10.0)]
    efficiency: Annotated[float, Gt(0.0), Le(1.0)]
    p0_w: Annotated[float, Ge(0.0), Le(1e5)]                      # avionics, always drawn
    battery_wh: Annotated[float, Gt(0.0), Le(1e6)]
    initial_soc_frac: Annotated[float, Ge(0.0), Le(1.0)]
    charge_power_w: Annotated[float, Gt(0.0), Le(1e6)]            # charger power on a pad (recharge step)
    low_battery_land_frac: Annotated[float, Ge(0.0), Lt(1.0)]   # abort the mission and land below this
    remaining_time_tau_s: Annotated[float, Gt(0.0), Le(3_600.0)]  # filter on power for remaining flight time
    model: Literal["momentum", "hover_actuator_disk"] = "momentum"
    # blade profile power (momentum model): tip speeds of drone propellers are ~50-250 m/s, solidity
    # 0.02-0.3, section drag coefficient 0.005-0.1
    tip_speed_m_s: Annotated[float, Gt(1.0), Le(340.0)] = 120.0
    rotor_solidity: Annotated[float, Gt(0.0), Le(1.0)] = 0.08
    blade_drag_coeff: Annotated[float, Ge(0.0), Le(1.0)] = 0.02
    air_density_kg_m3: Annotated[float, Ge(0.01), Le(2.0)] | None = None   # None: the world's air
    battery: Literal["lipo", "ideal"] = "lipo"
    # LiPo pack (battery: lipo), per cell; defaults: control.battery_ecm.LipoPackParams (a Tattu 22 Ah 6S
    # pack), cells from 1 to a 24S heavy lifter
    cells_series: Annotated[int, Ge(1), Le(24)] = 6
    cell_r0_ohm: Annotated[float, Ge(0.0), Le(1.0)] = 1.0e-3
    cell_r1_ohm: Annotated[float, Gt(0.0), Le(1.0)] = 0.627e-3
    rc_tau_s: Annotated[float, Gt(0.0), Le(1e4)] = 32.85
    cell_cutoff_v: Annotated[float, Ge(2.5), Le(4.0)] = 3.5
    cycles: Annotated[float, Ge(0.0), Le(1e5)] = 0.0              # equivalent full cycles already done
    cycle_life: Annotated[float, Gt(0.0), Le(1e5)] = 500.0        # cycles to eol_capacity_frac
    eol_capacity_frac: Annotated[float, Ge(0.0), Le(1.0)] = 0.8

    @property
    def design_capacity_ah(self) -> float:
        """The new pack's capacity [Ah]: ``battery_wh`` at ``cells_series`` x 3.7 V (a LiPo cell's nominal voltage)."""
        return self.battery_wh / (self.cells_series * LIPO_CELL_NOMINAL_V)

    @property
    def capacity_ah(self) -> float:
        """The capacity the pack holds now [Ah]: the design capacity faded by ``cycles`` (``lipo``;
        :func:`~unetyemu_ecs.control.battery_ecm.soh_frac`), the design capacity for the ``ideal`` battery."""
        if self.battery != "lipo":
            return self.design_capacity_ah
        from ..control.battery_ecm import soh_frac

        return self.design_capacity_ah * float(soh_frac(self.cycles, self.cycle_life, self.eol_capacity_frac))


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
