"""PX4-style attitude controller plugin for unetyemu_ecs (entry point ``px4_attitude`` in
``unetyemu_ecs.controllers``): tilt-prioritised quaternion attitude control, body-rate PID and a
vertical-speed PI(D), after PX4's mc_att_control, mc_rate_control and mc_pos_control. See
:mod:`unetyemu_px4_attitude.law`.
"""

from __future__ import annotations

from .law import MEMORY, Px4AttitudeParams, px4_attitude_law, torque_per_cmd_flu_n_m

try:
    from unetyemu_ecs.plugin_api import ControllerPlugin
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("unetyemu-px4-attitude is a plugin of the unetyemu_ecs simulator: install it into the "
                      "environment that has unetyemu_ecs (.venv/bin/pip install ./plugins/px4_attitude from the "
                      f"simulator's repository) ({exc})") from exc

PX4_ATTITUDE = ControllerPlugin(
    layer="attitude", params=Px4AttitudeParams, law=px4_attitude_law, memory=MEMORY,
    summary="PX4-style tilt-prioritised attitude P + body-rate PID + vertical-speed PI, gains in angular "
            "acceleration (airframe-independent)")

__all__ = ["MEMORY", "PX4_ATTITUDE", "Px4AttitudeParams", "px4_attitude_law", "torque_per_cmd_flu_n_m"]
