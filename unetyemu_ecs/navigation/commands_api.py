"""The Python API of the navigation modes: ``Simulation.takeoff``, ``land``, ``return_to_launch``,
``set_nav_mode``, ``set_param`` ... (a mixin of :class:`~unetyemu_ecs.app.Simulation`).

Each method checks its arguments with :mod:`unetyemu_ecs.command_checks` (``ValueError`` naming what
is wrong), queues the command and returns its id; the result (accepted, or rejected with a reason)
appears in :meth:`Simulation.command_result` after the next step. The same commands come from ROS 2 and MAVLink.
Positions are ENU metres (z = height above the world's ground plane), yaw in degrees ENU (0 = east,
counter-clockwise), like the rest of the API.
"""

from __future__ import annotations

from typing import Any

import esper
import numpy as np

from .. import command_checks as cc
from ..systems.flight_state import LandedState, MissionState, NavState
from ..transport.bus import (ChangeSpeed, FollowTargetFix, Gripper, Land, ManualControl, OffboardSetpoint, Orbit,
                             PauseMission, ReturnToLaunch, SetFenceEnabled, SetGeofence, SetHome, SetMissionCurrent,
                             SetNavMode, SetParam, SetRallyPoints, StartMission, StoreMission, Takeoff, Terminate)
from .params import PARAM_BY_NAME, FlightParams, FlightParamsSpec, params_from_spec


class NavigationApi:
    """Navigation-mode commands of a :class:`~unetyemu_ecs.app.Simulation` (mixed into it)."""

    # provided by Simulation
    inbox: Any
    layout: Any

    # -- modes -------------------------------------------------------------------------------
    def set_nav_mode(self, name: str, mode: str | int) -> int:
        """Switch drone ``name`` to navigation mode ``mode`` (a :class:`NavState` or its name: "HOLD",
        "TAKEOFF", "LAND", "RTL", "MISSION"). Returns the command id."""
        self._drone(name)
        return self.inbox.submit(SetNavMode(name, cc.check_nav_mode(name, mode)))

    def hold(self, name: str) -> int:
        """HOLD: brake and hover where the drone is (a running mission pauses)."""
        return self.set_nav_mode(name, NavState.HOLD)

    def takeoff(self, name: str, alt_m: float | None = None, yaw_deg: float | None = None) -> int:
        """TAKEOFF: climb straight up at MPC_TKO_SPEED to world height ``alt_m`` (None: home +
        MIS_TAKEOFF_ALT), then HOLD. The drone must be armed (else REJECTED_STATE ``not_armed``)."""
        self._drone(name)
        return self.inbox.submit(Takeoff(name, *cc.check_takeoff(name, alt_m, yaw_deg)))

    def land(self, name: str, xy: tuple[float, float] | None = None) -> int:
        """LAND at ENU ``xy`` (None: straight below): MPC_Z_V_AUTO_DN, then MPC_LAND_SPEED below
        MPC_LAND_ALT2; touchdown from the land detector; disarms COM_DISARM_LAND seconds later."""
        self._drone(name)
        return self.inbox.submit(Land(name, cc.check_land_xy(name, self.layout, xy)))

    def return_to_launch(self, name: str) -> int:
        """RTL: climb to RTL_RETURN_ALT above the closest of home and the rally points, fly there at
        MPC_XY_CRUISE, descend to RTL_DESCEND_ALT, wait RTL_LAND_DELAY, land and disarm."""
        self._drone(name)
        return self.inbox.submit(ReturnToLaunch(name))

    def offboard_setpoint(self, name: str, *, pos: tuple[float, float, float] | None = None,
                          vel_enu: tuple[float, float, float] | None = None,
                          vel_flu: tuple[float, float, float] | None = None, yaw_deg: float | None = None,
                          yaw_rate_rad_s: float | None = None) -> int:
        """One setpoint of an OFFBOARD stream: a position ``pos`` or a velocity (``vel_enu`` world frame,
        or ``vel_flu`` body frame forward/left/up) [m, m/s], a heading ``yaw_deg`` or a yaw rate (CCW).
        Stream them (faster than 1 / COM_OF_LOSS_T); ``set_nav_mode(name, "OFFBOARD")`` needs one from the
        last COM_OF_LOSS_T seconds; when they stop for that long, COM_OBL_RC_ACT's failsafe takes over."""
        self._drone(name)
        return self.inbox.submit(OffboardSetpoint(name, *cc.check_offboard_setpoint(
            name, self.layout, pos, vel_enu, vel_flu, yaw_deg, yaw_rate_rad_s)))

    def offboard_attitude(self, name: str, roll_deg: float, pitch_deg: float, thrust: float, *,
                          yaw_deg: float | None = None, yaw_rate_rad_s: float | None = None) -> int:
        """One attitude setpoint of an OFFBOARD stream (PX4: SET_ATTITUDE_TARGET): ``roll_deg`` (right side
        down positive) and ``pitch_deg`` (nose down positive) of the body in ENU, a heading ``yaw_deg`` (ENU,
        CCW from east) or a yaw rate (CCW; neither: no turn), and the collective ``thrust`` as a fraction of
        the four motors' maximum, applied as it is (no altitude hold: hover needs m g / (4 F_max), more
        with a tilt or a package). Streamed and lapsing like :meth:`offboard_setpoint`."""
        self._drone(name)
        yaw_rad, yaw_rate, rp, thrust_frac = cc.check_offboard_attitude(name, roll_deg, pitch_deg, thrust, yaw_deg,
                                                                         yaw_rate_rad_s)
        return self.inbox.submit(OffboardSetpoint(name, yaw_rad=yaw_rad, yaw_rate_rad_s=yaw_rate, attitude_rp_rad=rp,
                                                  thrust_frac=thrust_frac))

    def manual_control(self, name: str, pitch: float, roll: float, throttle: float, yaw: float) -> int:
        """Transmitter sticks (MAVLink MANUAL_CONTROL): ``pitch`` forward, ``roll`` right, ``yaw`` clockwise
        in [-1, 1], ``throttle`` in [0, 1] (0.5 = hold height). Flown in POSCTL (speeds) or MANUAL (tilt);
        stream them: after COM_RC_LOSS_T without one the drone holds, COM_FAIL_ACT_T later NAV_RCL_ACT."""
        self._drone(name)
        return self.inbox.submit(ManualControl(name, *cc.check_manual_control(name, pitch, roll, throttle, yaw)))

    def orbit(self, name: str, center: tuple[float, float, float], radius_m: float, speed_m_s: float = 1.0,
              yaw_behaviour: int = 0) -> int:
        """ORBIT: circle ENU ``center`` [m] at ``radius_m`` (> 0 clockwise seen from above) at ``speed_m_s``;
        ``yaw_behaviour`` as MAVLink's ORBIT_YAW_BEHAVIOUR (0 face the centre, 1 initial heading, 2 and 5
        uncontrolled, 3 along the circle)."""
        self._drone(name)
        return self.inbox.submit(Orbit(name, *cc.check_orbit(name, self.layout, center, radius_m, speed_m_s,
                                                             yaw_behaviour)))

    def follow_target_fix(self, name: str, pos: tuple[float, float, float],
                          vel: tuple[float, float, float] | None = None) -> int:
        """One fix of the target FOLLOW_TARGET follows (ENU position [m], velocity [m/s]); stream them."""
        self._drone(name)
        return self.inbox.submit(FollowTargetFix(name, *cc.check_follow_target(name, self.layout, pos, vel)))

    def set_geofence(self, name: str, fence: Any) -> int:
        """Replace the drone's geofence (a ``navigation.geofence.Geofence``; None: none). A breach triggers
        GF_ACTION; arming outside it is refused (``outside_fence``)."""
        from .geofence import Geofence

        self._drone(name)
        if fence is not None and not isinstance(fence, Geofence):
            raise ValueError(f"set_geofence({name!r}): expected a Geofence or None, got {type(fence).__name__}")
        return self.inbox.submit(SetGeofence(name, fence))

    def enable_geofence(self, name: str, enabled: bool) -> int:
        """Enable (True) or disable (False) the drone's geofence, as MAV_CMD_DO_FENCE_ENABLE does: disabled,
        a breach triggers nothing and arming outside is allowed; enabled again while outside, GF_ACTION
        applies at once. The fence itself (``set_geofence``, GF_MAX_*) is kept."""
        self._drone(name)
        return self.inbox.submit(SetFenceEnabled(name, cc.check_flag("enabled", enabled)))

    def terminate(self, name: str) -> int:
        """Flight termination: motors off now, wherever the drone is."""
        self._drone(name)
        return self.inbox.submit(Terminate(name))

    # -- missions ----------------------------------------------------------------------------
    def store_mission(self, name: str, mission: Any) -> int:
        """Keep ``mission`` (JSON text or a MissionSpec; None clears it) as the drone's mission without
        starting it (``mission_state`` STORED); :meth:`start_mission` or MISSION mode runs it."""
        self._drone(name)
        spec = None if mission is None else cc.check_mission(name, "store_mission", self.layout, self.package_names, mission)
        return self.inbox.submit(StoreMission(name, spec))

    def start_mission(self, name: str, first_step: int = 0) -> int:
        """Run the stored mission from ``first_step``; on the ground a mission whose step flies somewhere
        takes off first (to home + MIS_TAKEOFF_ALT or the first waypoint's height, the higher)."""
        self._drone(name)
        return self.inbox.submit(StartMission(name, cc.check_mission_step(name, first_step)))

    def set_mission_current(self, name: str, step: int) -> int:
        """Make ``step`` the mission's current step (flown next, or now if the mission runs)."""
        self._drone(name)
        return self.inbox.submit(SetMissionCurrent(name, cc.check_mission_step(name, step)))

    def pause_mission(self, name: str, resume: bool = False) -> int:
        """Pause the running mission (HOLD), or with ``resume`` continue it at its current step."""
        self._drone(name)
        return self.inbox.submit(PauseMission(name, cc.check_flag("resume", resume)))

    # -- parameters, home, speed, rally, gripper -------------------------------------------------
    def set_param(self, name: str, param: str, value: float) -> int:
        """Set flight parameter ``param`` (``navigation.params.PX4_PARAMS``) of drone ``name``."""
        self._drone(name)
        return self.inbox.submit(SetParam(name, *cc.check_param(name, param, value)))

    def set_home(self, name: str, pos: tuple[float, float, float] | None = None) -> int:
        """Set the home position to ENU ``pos`` [m] (None: where the drone is)."""
        self._drone(name)
        checked = None if pos is None else cc.check_position(f"set_home({name!r})", self.layout, pos)
        return self.inbox.submit(SetHome(name, checked))

    def change_speed(self, name: str, speed_m_s: float, which: str = "ground") -> int:
        """Change the ``which`` ("ground", "climb", "descent") speed of the current leg and of the
        automatic modes after it."""
        self._drone(name)
        kind, speed = cc.check_change_speed(name, which, speed_m_s)
        return self.inbox.submit(ChangeSpeed(name, kind, speed))

    def set_rally_points(self, name: str, points: list[tuple[float, float, float]]) -> int:
        """Replace the drone's rally points (ENU [m]); RTL goes to the closest of home and these."""
        self._drone(name)
        return self.inbox.submit(SetRallyPoints(name, cc.check_rally_points(name, self.layout, points)))

    def gripper(self, name: str, grab: bool) -> int:
        """Grab the package within reach (True) or release the one carried (False), now."""
        self._drone(name)
        return self.inbox.submit(Gripper(name, cc.check_flag("grab", grab)))

    # -- queries -----------------------------------------------------------------------------
    def _fleet_value(self, name: str, array: str) -> Any:
        self._drone(name)
        return getattr(self._context().fleet, array)[self.row(name)]

    def nav_state(self, name: str) -> str:
        """The drone's navigation mode (a :class:`NavState` name: "HOLD", "TAKEOFF", "RTL" ...)."""
        return NavState(int(self._fleet_value(name, "nav_state"))).name

    def landed_state(self, name: str) -> str:
        """The land detector's verdict: "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING" ("UNDEFINED" before the
        first step)."""
        return LandedState(int(self._fleet_value(name, "landed_state"))).name

    def mission_state(self, name: str) -> str:
        """The drone's mission state ("NONE", "STORED", "RUNNING", "PAUSED", "COMPLETED", "FAILED", "CANCELLED")."""
        return MissionState(int(self._fleet_value(name, "mission_state"))).name

    def is_armed(self, name: str) -> bool:
        """Whether the drone's motors are armed."""
        return int(self._fleet_value(name, "flight_mode")) != 0

    def home_enu_m(self, name: str) -> np.ndarray | None:
        """The drone's home position, ENU [m] (None before it is set: first fix or arming)."""
        if not self._fleet_value(name, "home_set"):
            return None
        return np.array(self._fleet_value(name, "home_enu_m"), dtype=float)

    def get_param(self, name: str, param: str) -> float:
        """The value of flight parameter ``param`` of drone ``name``."""
        ent = self._drone(name)
        if param not in PARAM_BY_NAME:
            raise ValueError(f"get_param({name!r}): unknown flight parameter {param!r}")
        with self.ecs.active():
            params = esper.try_component(ent, FlightParams)
            if params is None:
                params = params_from_spec(esper.try_component(ent, FlightParamsSpec))
        return params[param]
