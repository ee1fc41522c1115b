"""Body-rate control: the inner loop of the attitude layer on its own, for an agent that commands rates.

The built-in attitude law (:func:`~.attitude.attitude_to_torque_cmd`) is an angle P with a rate D:
``u = kp (angle_sp - angle) - kd rate``, which is a rate loop ``u = kd (rate_sp - rate)`` around the
rate setpoint ``rate_sp = (kp / kd) (angle_sp - angle)``. This module is that rate loop alone, with
the same gains, so a drone flown by collective thrust and body rates (acro, what racing pilots and
most learned controllers use) feels exactly the built-in stabilizer's inner loop.
"""

from __future__ import annotations

import numpy as np

from .attitude import StabilizerGains


def body_rates_to_torque_cmd(rate_sp_flu_rad_s: np.ndarray, rate_flu_rad_s: np.ndarray,
                             gains: StabilizerGains) -> np.ndarray:
    """Normalised ``[roll, pitch, yaw]`` torque commands (N, 3) in [-1, 1] that drive the body rates to
    their setpoints.

    rate_sp_flu_rad_s, rate_flu_rad_s : (N, 3) [rad/s], body FLU, right-handed (roll rate about x
        forward: positive puts the right side down; pitch rate about y left: positive puts the nose
        down; yaw rate about z up: positive turns left)
    gains : the attitude layer's gains (``gain_rate_d`` for roll and pitch, ``gain_yaw_rate_p`` for yaw),
        scalars or (N,) arrays
    """
    err = np.asarray(rate_sp_flu_rad_s, dtype=float) - np.asarray(rate_flu_rad_s, dtype=float)
    gain = np.stack(np.broadcast_arrays(gains.gain_rate_d, gains.gain_rate_d, gains.gain_yaw_rate_p), axis=-1)
    return np.clip(gain * err, -1.0, 1.0)


__all__ = ["body_rates_to_torque_cmd"]
