"""The controller layers of a vehicle and the typed arrays that flow between them.

A drone is flown by three replaceable layers, a car by one; each layer's controller is chosen per
vehicle in the world file (``controller: {attitude: ...}``) from the entry-point group
``unetyemu_ecs.controllers``, built-in ones included::

    route / sticks / cmd_vel          (framework: missions, pure pursuit, commands)
        | PositionSetpoint
    position layer   (GUIDANCE)       e.g. ``cascade_pid``
        | AttitudeSetpoint            (also what the sticks give in MANUAL mode)
    attitude layer   (STABILIZE)      e.g. ``angle_rate_pd``
        | ThrustTorqueCommand
    mixer layer      (ACTUATE)        e.g. ``x_quad_priority``
        | MotorCommand                (framework: motor lag, one force per motor, reaction torques)

    car: CarSetpoint -> drive layer (STABILIZE), e.g. ``speed_pi_steer`` -> CarCommand

Every controller is a *law*: a pure function over N vehicles at once (a single vehicle is a fleet
of one), with no esper and no PyBullet::

    law(setpoint, state, airframe, params, memory, dt_s) -> (command, new_memory)

``params`` is the controller's parameter dataclass with every field stacked into an (N,) array;
``memory`` maps each name the controller declared to an (N, ...) array of its per-vehicle state
(integrators, filters) and the law returns the new values. The framework keeps the memory in the
fleet arrays, resets it to its initial values while a drone is disarmed and when a vehicle enters a
position- or speed-controlled mode (AUTO, VELOCITY; a car's ROUTE, VELOCITY), and zeroes a disarmed
drone's command. Shapes are (N,) unless given; frames and units are in the names:
ENU world frame (x east, y north, z up), FLU body frame (x forward, y left, z up), yaw 0 = east,
counter-clockwise; positive roll = right side down, positive pitch = nose down.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np


class Layer(StrEnum):
    """A replaceable controller layer (its world-file key under ``controller:``)."""

    POSITION = "position"
    ATTITUDE = "attitude"
    MIXER = "mixer"
    DRIVE = "drive"


LAYERS_OF_KIND: dict[str, tuple[Layer, ...]] = {
    "quadrotor": (Layer.POSITION, Layer.ATTITUDE, Layer.MIXER),
    "car": (Layer.DRIVE,),
}

# the built-in controller of each layer, used where a vehicle's `controller:` block names none
DEFAULT_CONTROLLER: dict[Layer, str] = {
    Layer.POSITION: "cascade_pid",
    Layer.ATTITUDE: "angle_rate_pd",
    Layer.MIXER: "x_quad_priority",
    Layer.DRIVE: "speed_pi_steer",
}


# -- drones -------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class DroneState:
    """Measured state of N drones (ground truth from the physics)."""

    pos_enu_m: np.ndarray            # (N, 3) centre of mass
    vel_enu_m_s: np.ndarray          # (N, 3)
    acc_enu_m_s2: np.ndarray         # (N, 3) velocity change over the last step / dt
    quat_enu_flu_xyzw: np.ndarray    # (N, 4) attitude of the body FLU in ENU
    rate_flu_rad_s: np.ndarray       # (N, 3) body rates, FLU


@dataclass(frozen=True, slots=True)
class Airframe:
    """Constants of N airframes: what a controller may know about the vehicle it flies."""

    mass_kg: np.ndarray                  # nominal (unloaded) mass; a payload is for the controller to find
    inertia_flu_kg_m2: np.ndarray        # (N, 3) principal moments of inertia about the FLU axes
    max_thrust_per_motor_n: np.ndarray   # F_max of each of the four motors
    arm_length_m: np.ndarray             # centre of mass -> motor axis
    yaw_moment_coeff_m: np.ndarray       # rotor reaction torque / thrust
    motor_tau_s: np.ndarray              # first-order motor spin-up time constant (0: none)
    torque_per_cmd_flu_n_m: np.ndarray   # (N, 3) torque a ThrustTorqueCommand.torque_cmd of 1 stands for
    hover_thrust_frac: np.ndarray        # m g / (4 F_max) of the unloaded drone
    max_tilt_rad: np.ndarray             # guidance limits (world-file ``guidance``)
    lim_climb_m_s: np.ndarray
    lim_descent_m_s: np.ndarray
    lim_yaw_rate_rad_s: np.ndarray


@dataclass(frozen=True, slots=True)
class PositionSetpoint:
    """What route following or a velocity command asks of the position layer.

    Rows with a finite ``pos_enu_m`` fly to that point (for pure pursuit: the virtual target on the
    route) with ``dist_to_go_m`` still to fly along the route to its end (to arrive without
    overshooting) and at most ``speed_limit_m_s``; rows with NaN in ``pos_enu_m`` fly ``vel_enu_m_s``.
    Rows with a finite ``yaw_rad`` turn to that heading; NaN rows turn at ``yaw_rate_rad_s``.
    """

    pos_enu_m: np.ndarray          # (N, 3)
    vel_enu_m_s: np.ndarray        # (N, 3)
    speed_limit_m_s: np.ndarray    # (N, 3) horizontal, climb, descent (all >= 0)
    dist_to_go_m: np.ndarray
    yaw_rad: np.ndarray
    yaw_rate_rad_s: np.ndarray

    @property
    def flies_to_position(self) -> np.ndarray:
        """(N,) bool: the rows that fly to ``pos_enu_m`` (the others fly ``vel_enu_m_s``)."""
        return np.isfinite(self.pos_enu_m[:, 0])


@dataclass(frozen=True, slots=True)
class AttitudeSetpoint:
    """Input of the attitude layer: the same from guidance (AUTO, VELOCITY) and sticks (MANUAL)."""

    vz_m_s: np.ndarray             # vertical speed, up positive
    roll_rad: np.ndarray           # ZYX Euler roll of FLU in ENU, right side down positive
    pitch_rad: np.ndarray          # ZYX Euler pitch, nose down positive
    yaw_rate_rad_s: np.ndarray     # about the body z axis, counter-clockwise positive


@dataclass(frozen=True, slots=True)
class ThrustTorqueCommand:
    """Output of the attitude layer, input of the mixer, in normalised units."""

    thrust_frac: np.ndarray        # collective thrust as a fraction of 4 F_max, in [0, 1]
    torque_cmd: np.ndarray         # (N, 3) roll, pitch, yaw commands in [-1, 1]: a command of 1 at
    #                                mid collective drives one side's motors to F_max, the other to 0,
    #                                i.e. Airframe.torque_per_cmd_flu_n_m [N m] (control.mixer)


@dataclass(frozen=True, slots=True)
class MotorCommand:
    """Output of the mixer: each motor's thrust as a fraction of its F_max (FL, FR, BR, BL)."""

    motor_frac: np.ndarray         # (N, 4) in [0, 1]


# -- cars ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class CarState:
    """Measured state of N cars."""

    speed_m_s: np.ndarray          # forward speed along the body x axis (negative when reversing)
    yaw_rate_rad_s: np.ndarray     # about the body z axis, counter-clockwise positive
    steer_rad: np.ndarray          # applied bicycle-model steering angle, left positive
    throttle: np.ndarray           # applied in the last step, [-1, 1]
    brake: np.ndarray              # applied in the last step, [0, 1]


@dataclass(frozen=True, slots=True)
class CarChassis:
    """Constants of N cars."""

    mass_kg: np.ndarray
    wheelbase_m: np.ndarray
    track_m: np.ndarray
    wheel_radius_m: np.ndarray
    max_drive_torque_n_m: np.ndarray     # at the rear axle
    max_brake_torque_n_m: np.ndarray     # per wheel
    top_speed_m_s: np.ndarray
    rolling_resistance_coeff: np.ndarray


@dataclass(frozen=True, slots=True)
class CarSetpoint:
    """What the car's route following or velocity command asks of the drive layer (controlled rows
    only: manual and parked cars bypass the layer)."""

    speed_m_s: np.ndarray          # forward speed setpoint
    steer_rad: np.ndarray          # steering angle setpoint (route following); NaN: use yaw_rate_rad_s
    yaw_rate_rad_s: np.ndarray     # yaw-rate setpoint (cmd_vel)


@dataclass(frozen=True, slots=True)
class CarCommand:
    """Output of the drive layer."""

    throttle: np.ndarray           # [-1, 1], negative = reverse drive
    brake: np.ndarray              # [0, 1]
    steer_rad: np.ndarray          # steering angle setpoint; the framework limits it and its rate


INPUT_OF_LAYER = {Layer.POSITION: PositionSetpoint, Layer.ATTITUDE: AttitudeSetpoint,
                  Layer.MIXER: ThrustTorqueCommand, Layer.DRIVE: CarSetpoint}
OUTPUT_OF_LAYER = {Layer.POSITION: AttitudeSetpoint, Layer.ATTITUDE: ThrustTorqueCommand,
                   Layer.MIXER: MotorCommand, Layer.DRIVE: CarCommand}

__all__ = ["DEFAULT_CONTROLLER", "INPUT_OF_LAYER", "LAYERS_OF_KIND", "OUTPUT_OF_LAYER", "Airframe", "AttitudeSetpoint", "CarChassis",
           "CarCommand", "CarSetpoint", "CarState", "DroneState", "Layer", "MotorCommand", "PositionSetpoint",
           "ThrustTorqueCommand"]
