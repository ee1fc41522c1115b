"""Per-drone flight state shared by the flight-stack systems: modes, routes, fleet arrays.

Every array is declared on the :class:`~unetyemu_ecs.fleet.FleetState` (one row per body; only
quadrotor rows are used), so the whole flight state of the fleet lives in one place and each phase
works on it in one vectorised pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..fleet import FleetState


class FlightMode(IntEnum):
    """How a drone is being flown."""

    DISARMED = 0   # motors off
    MANUAL = 1     # teleop sticks -> stabilizer setpoints
    AUTO = 2       # route / target -> guidance -> stabilizer setpoints
    VELOCITY = 3   # body-frame velocity + yaw rate (ROS cmd_vel) -> guidance velocity loop
    ATTITUDE = 4   # OFFBOARD roll, pitch, yaw (rate) and collective thrust -> attitude layer; the thrust
    #                bypasses its vertical-speed loop (MAVLink SET_ATTITUDE_TARGET)


class NavState(IntEnum):
    """What the drone is doing, in PX4's terms (its navigation state); reported over MAVLink as PX4's
    custom main/sub mode, and usable from Python and ROS 2 alike. ``flight_mode`` says which control
    path flies it (AUTO route, VELOCITY, MANUAL sticks); ``nav_state`` says why."""

    HOLD = 0           # brake and hold position (PX4 AUTO.LOITER); also what a disarmed drone on the ground reports
    TAKEOFF = 1        # climb vertically to the takeoff altitude, then HOLD
    LAND = 2           # descend, detect touchdown, disarm after COM_DISARM_LAND
    RTL = 3            # climb to RTL_RETURN_ALT, fly to home / the closest rally point, land
    MISSION = 4        # run the mission (uploaded, or loaded from JSON)
    OFFBOARD = 5       # follow an external setpoint stream (SET_POSITION_TARGET_*, cmd_vel)
    POSCTL = 6         # sticks command velocity; centred sticks hold position
    MANUAL = 7         # sticks command attitude and thrust (teleop)
    ORBIT = 8          # circle a point
    FOLLOW_TARGET = 9  # follow a moving target's position stream
    GOTO = 10          # fly to one target (API set_target, ROS 2 target, DO_REPOSITION), then hold


class LandedState(IntEnum):
    """Landed state derived from the physics (values of MAVLink's MAV_LANDED_STATE)."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class ArmBlock(IntEnum):
    """Why a drone would be refused arming now (``arm_block``, written every step by the navigator from
    the same check the Arm command applies); NONE: it would arm. ``name.lower()`` is the refusal's reason."""

    NONE = 0
    LOW_BATTERY = 1       # battery below its low-battery level
    OVERWEIGHT = 2        # the package weighs more than the drone may lift (motors disabled)
    MOTORS_DISABLED = 3   # motors off for another reason (empty battery)
    OUTSIDE_FENCE = 4     # outside its (enabled) geofence
    IN_AIR = 5            # not on the ground


ARM_BLOCK_TEXT = {ArmBlock.NONE: "", ArmBlock.LOW_BATTERY: "low battery", ArmBlock.OVERWEIGHT: "payload too heavy",
                  ArmBlock.MOTORS_DISABLED: "motors disabled", ArmBlock.OUTSIDE_FENCE: "outside the geofence",
                  ArmBlock.IN_AIR: "not on the ground"}


class MissionState(IntEnum):
    """State of a drone's mission (``mission_state``), as a number transports can read."""

    NONE = 0          # no mission
    STORED = 1        # uploaded, not started
    RUNNING = 2
    PAUSED = 3
    COMPLETED = 4
    FAILED = 5
    CANCELLED = 6


class PayloadRequest(IntEnum):
    """What the mission asks the payload system to do this step (``payload_request``)."""

    NONE = 0
    ATTACH = 1
    RELEASE = 2


class PayloadResult(IntEnum):
    """What the payload system did (``payload_result``), read by the mission next step."""

    NONE = 0
    ATTACHED = 1
    RELEASED = 2
    NOTHING_IN_REACH = 3
    OVERWEIGHT = 4


# The members per-step code compares with numpy arrays, as plain ints: numpy looks an IntEnum operand's type
# up for its array protocols (failed lookups through the enum's metaclass, microseconds per comparison).
MODE_DISARMED, MODE_MANUAL, MODE_AUTO = int(FlightMode.DISARMED), int(FlightMode.MANUAL), int(FlightMode.AUTO)
MODE_VELOCITY, MODE_ATTITUDE = int(FlightMode.VELOCITY), int(FlightMode.ATTITUDE)
NAV_OFFBOARD, NAV_POSCTL, NAV_MANUAL = int(NavState.OFFBOARD), int(NavState.POSCTL), int(NavState.MANUAL)
NAV_TAKEOFF, NAV_MISSION = int(NavState.TAKEOFF), int(NavState.MISSION)
LANDED_UNDEFINED, LANDED_ON_GROUND = int(LandedState.UNDEFINED), int(LandedState.ON_GROUND)
LANDED_IN_AIR = int(LandedState.IN_AIR)
MISSION_RUNNING = int(MissionState.RUNNING)
REQUEST_NONE = int(PayloadRequest.NONE)


@dataclass(frozen=True)
class Route:
    """A polyline to follow: point 0 is where the drone was when the route was given.

    points_enu_m : (W, 3) [m], ENU, W >= 2
    speeds_m_s : (W, 3) [m/s], (cruise, climb, descent) at each point
    yaw_sp_rad : heading to hold, ENU (NaN: keep the current heading)
    """

    points_enu_m: np.ndarray
    speeds_m_s: np.ndarray
    yaw_sp_rad: float

    def __post_init__(self) -> None:
        if self.points_enu_m.ndim != 2 or self.points_enu_m.shape[1] != 3 or self.points_enu_m.shape[0] < 2:
            raise ValueError(f"route points must be (W >= 2, 3), got {self.points_enu_m.shape}")
        if self.speeds_m_s.shape != self.points_enu_m.shape:
            raise ValueError("route speeds must have the shape of its points")


# name -> (tail shape, dtype, fill)
# name -> (tail shape, dtype, fill); each group names the systems that write it. Hand-overs between
# them are explicit: the mission sets payload_request and clears payload_result before the payload
# bay answers in it; the mission sets charging (and a step's charge_power_w), the energy system
# turns it into energy; the payload bay (overweight) and the energy system (empty) clear motors_enabled.
FLIGHT_ARRAYS: dict[str, tuple[tuple[int, ...], type, float]] = {
    # commands and missions (FlightCommandSystem, MissionSystem, EmergencyLandingSystem)
    "flight_mode": ((), np.int8, 0),
    "cmd_hold_until_s": ((), np.float64, np.inf),     # sim time a streamed teleop/cmd_vel lapses (inf: held)
    "motors_enabled": ((), np.bool_, True),            # False: motors stop (overweight payload, empty battery)
    "stick": ((4,), np.float64, 0.0),                 # [throttle, pitch, roll, yaw] in [-1, 1]
    "route_stamp": ((), np.int64, 0),                 # bumped whenever `route` changes (set_route)
    "has_route": ((), np.bool_, False),               # `route` is not None
    "mission_step": ((), np.int64, -1),               # index of the running mission step, -1 none
    "vel_cmd_flu_m_s": ((3,), np.float64, 0.0),       # VELOCITY mode: [forward, left, up], body frame
    "yaw_rate_cmd_rad_s": ((), np.float64, 0.0),      # VELOCITY mode: CCW positive
    "payload_request": ((), np.int8, 0),              # PayloadRequest: what the mission asks of the payload bay
    "charging": ((), np.bool_, False),                # a recharge step on a pad
    # navigation (the navigator and landed detector; docs/architecture.md §7)
    "nav_state": ((), np.int8, 0),                    # NavState
    "landed_state": ((), np.int8, 0),                 # LandedState, from contact and motion
    "home_enu_m": ((3,), np.float64, 0.0),            # home position (set at first fix and at arming)
    "home_set": ((), np.bool_, False),
    "mission_state": ((), np.int8, 0),                # MissionState of the drone's mission
    "arm_block": ((), np.int8, 0),                    # ArmBlock: why arming would be refused now (0: it would arm)
    # route following (RouteFollowingSystem)
    "route_segment": ((), np.int64, 0),
    "arrived": ((), np.bool_, False),                 # within arrival radius of the route's end
    "dist_to_final_m": ((), np.float64, 0.0),
    "cross_track_m": ((), np.float64, 0.0),
    # position-layer setpoint (control.layers.PositionSetpoint), written by route following
    "pos_sp_enu_m": ((3,), np.float64, 0.0),          # virtual target on the route; NaN: fly vel_sp_enu_m_s
    "vel_sp_enu_m_s": ((3,), np.float64, 0.0),        # commanded velocity (VELOCITY mode), ENU
    "speed_limit_m_s": ((3,), np.float64, 0.0),       # horizontal, climb, descent caps of the current leg
    "dist_to_go_m": ((), np.float64, 0.0),            # along the route to its end
    "yaw_sp_rad": ((), np.float64, np.nan),           # heading to hold, ENU; NaN: turn at yaw_rate_cmd_rad_s
    # attitude-layer setpoint (control.layers.AttitudeSetpoint), from the position layer or the sticks
    "vz_sp_m_s": ((), np.float64, 0.0),
    "roll_sp_rad": ((), np.float64, 0.0),
    "pitch_sp_rad": ((), np.float64, 0.0),
    "yaw_rate_sp_rad_s": ((), np.float64, 0.0),
    "thrust_cmd_frac": ((), np.float64, 0.0),         # ATTITUDE mode: commanded collective thrust, fraction of 4 F_max
    # attitude-layer command (control.layers.ThrustTorqueCommand), the mixer's input
    "thrust_frac_sp": ((), np.float64, 0.0),          # collective, fraction of 4 F_max
    "torque_cmd": ((3,), np.float64, 0.0),            # normalised [roll, pitch, yaw]
    "motor_frac_cmd": ((4,), np.float64, 0.0),        # the mixer's output: FL, FR, BR, BL fractions of F_max
    # motors (MotorSystem)
    "motor_thrust_cmd_n": ((4,), np.float64, 0.0),    # FL, FR, BR, BL
    "motor_thrust_n": ((4,), np.float64, 0.0),        # after lag: what is applied (ground effect included)
    "ground_effect_factor": ((4,), np.float64, 1.0),  # applied / out-of-ground-effect thrust (1 = none)
    # energy (EnergySystem)
    "power_w": ((), np.float64, 0.0),
    "power_filt_w": ((), np.float64, 0.0),
    "energy_j": ((), np.float64, 0.0),                # left in the battery
    "energy_used_j": ((), np.float64, 0.0),
    "soc_frac": ((), np.float64, 1.0),
    "remaining_time_s": ((), np.float64, np.inf),
    "charge_power_w": ((), np.float64, 0.0),
    "low_battery": ((), np.bool_, False),
    "pack_voltage_v": ((), np.float64, 0.0),          # terminal voltage of the battery pack
    "pack_current_a": ((), np.float64, 0.0),          # + = discharging
    "pack_v_rc_v": ((), np.float64, 0.0),             # voltage across the pack's RC pair (LiPo model)
    "glauert_inflow_m_s": ((4,), np.float64, 0.0),    # Glauert's inflow V_c + v_i of each rotor (momentum model)
    # payload bay (PayloadSystem)
    "payload_kg": ((), np.float64, 0.0),
    "payload_entity": ((), np.int64, -1),             # esper entity of the package carried (-1: none)
    "payload_result": ((), np.int8, 0),               # PayloadResult of the last request
}


def declare_flight_arrays(fleet: FleetState) -> None:
    """Declare every flight array on ``fleet`` (idempotent), plus the per-row route objects."""
    for name, (tail, dtype, fill) in FLIGHT_ARRAYS.items():
        fleet.declare(name, tail, dtype, fill)
    fleet.declare("route", (), object, None)
    fleet.declare("payload_package", (), object, None)     # name of the package a pickup asks for (None: nearest)


def set_route(fleet: FleetState, row: int, route: Route | None) -> None:
    """Give drone ``row`` a new route (None clears it) and restart following from its first segment.

    A route without a heading (NaN ``yaw_sp_rad``) holds the heading the drone has now."""
    from ..frames import yaw_rad_from_quat_xyzw

    fleet.route[row] = route
    fleet.has_route[row] = route is not None
    if route is not None:
        fleet.yaw_sp_rad[row] = (float(yaw_rad_from_quat_xyzw(fleet.quat_enu_flu_xyzw[row])) if np.isnan(route.yaw_sp_rad)
                                 else route.yaw_sp_rad)
    fleet.route_stamp[row] += 1
    fleet.route_segment[row] = 0
    fleet.arrived[row] = False
