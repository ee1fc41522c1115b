"""The systems that run each vehicle's chosen controller of each layer (see :mod:`..control.layers`).

For every controller in use the simulation adds one system, made by :func:`controller_system`:
its rows are the vehicles that carry that controller's parameter component, so a vehicle whose
layer was replaced is simply not in the built-in controller's rows (nothing of the built-in runs
for it, no integrator winds up in the background). The system gathers the rows and stacks the
parameters when the ECS changes, builds the layer's typed setpoint and state from the fleet
arrays, calls the law once for all its rows, and writes the command back:

========== ========= ================================================ =====================================
layer      phase     reads (fleet arrays)                             writes
========== ========= ================================================ =====================================
position   GUIDANCE  pos_sp_enu_m, vel_sp_enu_m_s, speed_limit_m_s,   vz_sp_m_s, roll_sp_rad, pitch_sp_rad,
                     dist_to_go_m, yaw_sp_rad, yaw_rate_cmd_rad_s     yaw_rate_sp_rad_s
attitude   STABILIZE those four setpoints (from the sticks in MANUAL;  thrust_frac_sp, torque_cmd
                     thrust_cmd_frac replaces the thrust in ATTITUDE)
mixer      ACTUATE   thrust_frac_sp, torque_cmd                       motor_frac_cmd
drive      STABILIZE car_speed_sp_m_s, car_steer_sp_rad, cmd_vel       car_throttle, car_brake, car_steer_rad
========== ========= ================================================ =====================================

A law's memory lives in fleet arrays named ``ctl_<params class>_<name>``; it is reset to its
initial value while a drone is disarmed, and when a drone enters a position-controlled mode (AUTO
or VELOCITY) from another mode.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any, ClassVar

import numpy as np

from ..components.body import RigidBody
from ..components.flight import GuidanceLimits, QuadrotorMotors
from ..control.attitude import manual_to_setpoints
from ..control.compiled import jit
from ..control.mixer import torque_per_unit_cmd_flu_n_m
from ..control.layers import (OUTPUT_OF_LAYER, Airframe, AttitudeSetpoint, DroneState, Layer, PositionSetpoint,
                              ThrustTorqueCommand)
from ..phases import Phase
from ..plugins import ControllerPlugin
from ..units import GRAVITY_M_S2
from ..world import StepContext
from .fleet_system import FleetSystem, read_only, stack_params, take_params
from .flight_state import MODE_ATTITUDE, MODE_AUTO, MODE_DISARMED, MODE_MANUAL, MODE_VELOCITY, FlightMode

# the fleet arrays of a law's typed inputs, in the order of their fields
DRONE_STATE_ARRAYS = ("pos_enu_m", "vel_enu_m_s", "acc_enu_m_s2", "quat_enu_flu_xyzw", "rate_flu_rad_s")
POSITION_SETPOINT_ARRAYS = ("pos_sp_enu_m", "vel_sp_enu_m_s", "speed_limit_m_s", "dist_to_go_m", "yaw_sp_rad",
                            "yaw_rate_cmd_rad_s")
ATTITUDE_SETPOINT_ARRAYS = ("vz_sp_m_s", "roll_sp_rad", "pitch_sp_rad", "yaw_rate_sp_rad_s")


def box_inertia_flu_kg_m2(mass_kg: np.ndarray, half_extents_m: np.ndarray) -> np.ndarray:
    """Principal moments (N, 3) [kg m^2] of uniform boxes (what PyBullet gives a box body)."""
    h2 = np.asarray(half_extents_m, dtype=float).reshape(-1, 3) ** 2
    m = np.asarray(mass_kg, dtype=float).reshape(-1, 1)
    return m / 3.0 * np.stack([h2[:, 1] + h2[:, 2], h2[:, 0] + h2[:, 2], h2[:, 0] + h2[:, 1]], axis=1)


def finite_or_zero(values: Any) -> np.ndarray:
    """A law's output as a float array with NaN and infinities replaced by 0 (checked cheaply first)."""
    out = np.asarray(values, dtype=float)
    return out if np.isfinite(out).all() else np.where(np.isfinite(out), out, 0.0)


@jit
def _unit_fractions_into(values, rows, out):
    """``out[rows]`` (N, K) = ``values`` (N, K) clamped to [0, 1], NaN and infinities 0 (``finite_or_zero`` then the
    clamp, ordered as numpy's ``minimum(maximum(x, 0), 1)``)."""
    for k in range(values.shape[0]):
        for j in range(values.shape[1]):
            v = values[k, j]
            out[rows[k], j] = min(1.0, max(0.0, v)) if np.isfinite(v) else 0.0


@jit
def _note_entries(mode, engaged, mode_seen, entered):
    """``entered`` (N,) bool: the engaged rows whose mode differs from ``mode_seen``, which becomes ``mode``;
    returns how many entered."""
    n = 0
    for k in range(mode.shape[0]):
        e = engaged[k] and mode[k] != mode_seen[k]
        entered[k] = e
        n += e
        mode_seen[k] = mode[k]
    return n


@jit
def _position_engaged(mode, has_route, active):
    """``active`` (N,) bool: the rows flying AUTO with a route or VELOCITY; returns how many."""
    n = 0
    for k in range(mode.shape[0]):
        a = (mode[k] == MODE_AUTO and has_route[k]) or mode[k] == MODE_VELOCITY
        active[k] = a
        n += a
    return n


@jit
def _count_modes(mode, counts):
    """``counts[m]``: how many rows are in flight mode ``m`` (modes outside the array's range are not counted)."""
    counts[:] = 0
    for k in range(mode.shape[0]):
        if 0 <= mode[k] < counts.shape[0]:
            counts[mode[k]] += 1


class ControllerSystem(FleetSystem):
    """Runs one registered controller for the vehicles that chose it; subclassed per layer, then
    per controller by :func:`controller_system`."""

    plugin: ClassVar[ControllerPlugin]
    key: ClassVar[str] = ""
    mode_array: ClassVar[str] = ""     # fleet array of the mode whose entry restarts the memory ("": none)

    def gather(self, ctx: StepContext) -> None:
        f = ctx.fleet
        self.params = stack_params(self.components[0], self.plugin.params)
        self._memory_names = {}
        for name, (tail, initial) in self.plugin.memory.items():
            array_name = f"ctl_{self.plugin.params.__name__}_{name}"
            f.declare(array_name, tuple(tail), np.float64, float(initial))
            self._memory_names[name] = array_name
        if self.mode_array:
            self._mode_seen = getattr(f, self.mode_array)[self.rows].copy()
            self._entered = np.zeros(self.rows.size, dtype=bool)
        self._views: dict[type, Any] = {}
        self._taken: tuple[bytes, tuple[Any, ...], tuple[Any, ...]] | None = None   # the last take_rows: k, in, out

    def take_rows(self, k: np.ndarray, *stacked: Any) -> tuple[Any, ...]:
        """The stacked parameter objects ``stacked`` at the local indices ``k`` (all of them: as they are); kept
        while the same rows are asked for (they change with a mode, not every step)."""
        if k.size == self.rows.size:
            return stacked
        key, kept = k.tobytes(), self._taken
        if kept is None or kept[0] != key or any(a is not b for a, b in zip(kept[1], stacked)):
            kept = self._taken = (key, stacked, tuple(take_params(s, k) for s in stacked))
        return kept[2]

    def fleet_view(self, ctx: StepContext, cls: type, names: tuple[str, ...], rows: slice | np.ndarray) -> Any:
        """``cls(*arrays)`` of the read-only fleet arrays ``names`` at ``rows``. For all the rows as a slice it
        is built once per gather: its arrays are views, which show the fleet's values of every step (the
        fleet reallocates its arrays only when rows change, and then the system gathers again)."""
        if isinstance(rows, slice) and rows is self.sel:
            view = self._views.get(cls)
            if view is None:
                view = self._views[cls] = cls(*(read_only(getattr(ctx.fleet, n)[rows]) for n in names))
            return view
        return cls(*(read_only(getattr(ctx.fleet, n)[rows]) for n in names))

    def restart_on_entry(self, ctx: StepContext, mode: np.ndarray, engaged: np.ndarray) -> None:
        """Reset the memory of the rows that entered a mode this layer controls since the last step
        (``mode``: the rows' modes now, from ``mode_array``; ``engaged``: the rows the layer controls)."""
        if _note_entries(mode, engaged, self._mode_seen, self._entered):
            self.reset_memory(ctx, self.rows[self._entered])

    def read_memory(self, ctx: StepContext, rows: slice | np.ndarray) -> dict[str, np.ndarray]:
        """The law's memory of ``rows``: copies (a law may update them in place)."""
        f = ctx.fleet
        return {name: getattr(f, arr)[rows].copy() for name, arr in self._memory_names.items()}

    def write_memory(self, ctx: StepContext, rows: slice | np.ndarray, memory: dict[str, np.ndarray]) -> None:
        f = ctx.fleet
        for name, arr in self._memory_names.items():
            try:
                value = memory[name]
            except KeyError:
                raise KeyError(f"controller {self.key!r} returned no memory {name!r}") from None
            getattr(f, arr)[rows] = value

    def reset_memory(self, ctx: StepContext, rows: np.ndarray) -> None:
        """Back to the declared initial values for ``rows``."""
        for name, arr in self._memory_names.items():
            getattr(ctx.fleet, arr)[rows] = float(self.plugin.memory[name][1])

    def call_law(self, ctx: StepContext, setpoint: Any, state: Any, frame: Any, params: Any, rows: np.ndarray) -> Any:
        """Run the law for ``rows``, store its memory and return its command; a law that fails or
        returns something else than its layer's command type is reported by name."""
        layer = self.plugin.layer
        try:
            command, memory = self.plugin.law(setpoint, state, frame, params, self.read_memory(ctx, rows), ctx.dt_s)
            if not isinstance(command, OUTPUT_OF_LAYER[layer]):
                raise TypeError(f"it returned a {type(command).__name__}, not a {OUTPUT_OF_LAYER[layer].__name__}")
            self.write_memory(ctx, rows, memory)
        except Exception as exc:
            raise RuntimeError(f"{layer} controller {self.key!r} failed at t = {ctx.sim_time_s:.4f} s: "
                               f"{type(exc).__name__}: {exc}") from exc
        return command


class DroneControllerSystem(ControllerSystem):
    """A drone layer: rows with the controller's parameters, motors, guidance limits and a body."""

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        _, motors, limits, bodies = self.components
        mass = np.array([b.mass_kg for b in bodies])
        f_max = np.array([m.max_thrust_per_motor_n for m in motors])
        self.airframe = Airframe(
            mass_kg=mass,
            inertia_flu_kg_m2=box_inertia_flu_kg_m2(mass, np.array([b.half_extents_m for b in bodies]).reshape(-1, 3)),
            max_thrust_per_motor_n=f_max,
            arm_length_m=np.array([m.arm_length_m for m in motors]),
            yaw_moment_coeff_m=np.array([m.yaw_moment_coeff_m for m in motors]),
            motor_tau_s=np.array([m.motor_tau_s for m in motors], dtype=float),
            torque_per_cmd_flu_n_m=torque_per_unit_cmd_flu_n_m(f_max, [m.arm_length_m for m in motors],
                                                               [m.yaw_moment_coeff_m for m in motors]),
            hover_thrust_frac=mass * GRAVITY_M_S2 / (4.0 * f_max),
            max_tilt_rad=np.deg2rad([lim.max_tilt_deg for lim in limits]),
            lim_climb_m_s=np.array([lim.lim_climb_m_s for lim in limits], dtype=float),
            lim_descent_m_s=np.array([lim.lim_descent_m_s for lim in limits], dtype=float),
            lim_yaw_rate_rad_s=np.deg2rad([lim.lim_yaw_rate_deg_s for lim in limits]))

    def state(self, ctx: StepContext, rows: slice | np.ndarray) -> DroneState:
        """The drones' state for a law: read-only (for a slice of rows, views of the fleet arrays)."""
        return self.fleet_view(ctx, DroneState, DRONE_STATE_ARRAYS, rows)

    def subset(self, k: np.ndarray) -> tuple[Any, Any]:
        """Parameters and airframe of the local indices ``k`` (all of them: the stacked ones as they are)."""
        return self.take_rows(k, self.params, self.airframe)


class PositionControllerSystem(DroneControllerSystem):
    """Position layer: PositionSetpoint -> AttitudeSetpoint for the AUTO (with a route) and VELOCITY rows."""

    phase = Phase.GUIDANCE
    order = 10
    mode_array = "flight_mode"

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        self._active = np.zeros(self.rows.size, dtype=bool)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        mode = f.flight_mode[self.sel]
        active = self._active
        n_active = _position_engaged(mode, f.has_route[self.sel], active)
        self.restart_on_entry(ctx, mode, active)
        if n_active == 0:
            return
        if n_active == self.rows.size:
            r, params, airframe = self.sel, self.params, self.airframe
        else:
            k = active.nonzero()[0]
            r = self.rows[k]
            params, airframe = self.subset(k)
        sp = self.fleet_view(ctx, PositionSetpoint, POSITION_SETPOINT_ARRAYS, r)
        out: AttitudeSetpoint = self.call_law(ctx, sp, self.state(ctx, r), airframe, params, r)
        f.vz_sp_m_s[r] = out.vz_m_s
        f.roll_sp_rad[r] = out.roll_rad
        f.pitch_sp_rad[r] = out.pitch_rad
        f.yaw_rate_sp_rad_s[r] = out.yaw_rate_rad_s


class AttitudeControllerSystem(DroneControllerSystem):
    """Attitude layer: AttitudeSetpoint -> ThrustTorqueCommand for every drone (zero while disarmed).

    MANUAL rows take their setpoint from the sticks first (``manual_to_setpoints``), so manual and
    automatic flight feed the same loops with the same memory: switching causes no jump. ATTITUDE rows
    (OFFBOARD attitude + thrust) fly the roll, pitch and yaw rate the navigator wrote with the commanded
    collective thrust ``thrust_cmd_frac`` in place of the law's: their vertical-speed setpoint is the
    measured one, so a law's vertical-speed loop neither acts nor winds up meanwhile.
    """

    phase = Phase.STABILIZE
    order = 0

    def gather(self, ctx: StepContext) -> None:
        super().gather(ctx)
        self._mode_counts = np.zeros(len(FlightMode), dtype=np.intp)

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        mode = f.flight_mode[r]
        counts = self._mode_counts
        _count_modes(mode, counts)
        if counts[MODE_MANUAL]:
            manual = mode == MODE_MANUAL
            a, rm = self.airframe, self.rows[manual]
            vz_sp, roll_sp, pitch_sp, yaw_rate_sp = manual_to_setpoints(
                f.stick[rm], a.max_tilt_rad[manual], a.lim_climb_m_s[manual], a.lim_descent_m_s[manual],
                a.lim_yaw_rate_rad_s[manual])
            f.vz_sp_m_s[rm] = vz_sp
            f.roll_sp_rad[rm] = roll_sp
            f.pitch_sp_rad[rm] = pitch_sp
            f.yaw_rate_sp_rad_s[rm] = yaw_rate_sp
        attitude = None
        if counts[MODE_ATTITUDE]:
            attitude = mode == MODE_ATTITUDE
            ra = self.rows[attitude]
            f.vz_sp_m_s[ra] = f.vel_enu_m_s[ra, 2]
        sp = self.fleet_view(ctx, AttitudeSetpoint, ATTITUDE_SETPOINT_ARRAYS, r)
        out: ThrustTorqueCommand = self.call_law(ctx, sp, self.state(ctx, r), self.airframe, self.params, r)
        thrust = out.thrust_frac if attitude is None else np.where(attitude, f.thrust_cmd_frac[r], out.thrust_frac)
        if counts[MODE_DISARMED] == 0:
            f.thrust_frac_sp[r] = thrust
            f.torque_cmd[r] = out.torque_cmd
        else:
            armed = mode != MODE_DISARMED
            f.thrust_frac_sp[r] = np.where(armed, thrust, 0.0)
            f.torque_cmd[r] = np.where(armed[:, None], out.torque_cmd, 0.0)
            self.reset_memory(ctx, self.rows[~armed])


class MixerSystem(DroneControllerSystem):
    """Mixer layer: ThrustTorqueCommand -> MotorCommand (motor_frac_cmd) for every drone."""

    phase = Phase.ACTUATE
    order = 15

    def update(self, ctx: StepContext) -> None:
        f = ctx.fleet
        r = self.sel
        cmd = self.fleet_view(ctx, ThrustTorqueCommand, ("thrust_frac_sp", "torque_cmd"), r)
        out = self.call_law(ctx, cmd, self.state(ctx, r), self.airframe, self.params, r)
        motor_frac = np.asarray(out.motor_frac, dtype=float)
        if motor_frac.shape == (self.rows.size, 4):
            _unit_fractions_into(motor_frac, self.rows, f.motor_frac_cmd)   # NaN and infinities 0, clamped to [0, 1]
        else:                                                               # what numpy broadcasts, or its error
            f.motor_frac_cmd[r] = np.minimum(np.maximum(finite_or_zero(motor_frac), 0.0), 1.0)
        if self._memory_names:
            disarmed = f.flight_mode[r] == MODE_DISARMED
            if disarmed.any():
                self.reset_memory(ctx, self.rows[disarmed])


def layer_system(layer: Layer) -> tuple[type[ControllerSystem], tuple[type, ...]]:
    """The system class of ``layer`` and the components (besides the controller's params) of its rows."""
    drone = (QuadrotorMotors, GuidanceLimits, RigidBody)
    if layer == Layer.DRIVE:
        car_drive = import_module(".car_drive", __package__)   # it builds on this module
        return car_drive.DriveControllerSystem, car_drive.DRIVE_REQUIRES
    return {Layer.POSITION: PositionControllerSystem, Layer.ATTITUDE: AttitudeControllerSystem,
            Layer.MIXER: MixerSystem}[layer], drone


def controller_system(key: str, plugin: ControllerPlugin) -> ControllerSystem:
    """A new system running controller ``key`` (a class of its own: esper keeps one system per class)."""
    base, requires = layer_system(plugin.layer)
    cls = type(f"{base.__name__}[{key}]", (base,), {"plugin": plugin, "key": key,
                                                    "requires": (plugin.params, *requires)})
    return cls()


__all__ = ["AttitudeControllerSystem", "ControllerSystem", "MixerSystem", "PositionControllerSystem",
           "box_inertia_flu_kg_m2", "controller_system", "finite_or_zero", "layer_system"]
