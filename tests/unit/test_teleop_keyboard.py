"""Keyboard teleop key mapping (pure: no terminal, no DDS)."""

from __future__ import annotations

import numpy as np

from unetyemu_ecs.teleop_keyboard import apply_key


def test_keyboard_teleop_keys_step_each_axis_within_its_range():
    v = np.zeros(4)
    for key in "w" * 15 + "jjaa":
        v = apply_key("drone", v, key)
    assert list(np.round(v, 3)) == [1.0, 0.0, -0.2, 0.2]        # throttle capped at +1, roll left, yaw left
    assert list(apply_key("drone", v, " ")) == [0.0] * 4
    car = apply_key("car", np.array([0.0, 1.0, 0.0]), "n")
    assert list(np.round(apply_key("car", car, "d"), 3)) == [0.0, 0.9, -0.1]
    assert list(apply_key("car", np.array([0.5, 0.0, 0.3]), " ")) == [0.0, 1.0, 0.0]
