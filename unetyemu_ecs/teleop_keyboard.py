"""``unetyemu teleop VEHICLE``: drive a vehicle from the keyboard over ROS 2 (DDS), no ROS installed.

Publishes ``std_msgs/Float32MultiArray`` on ``/<vehicle>/teleop`` at 20 Hz: the drone layout
``[throttle, pitch, roll, yaw]`` or the car layout ``[throttle, brake, steering]``, each in its range.
Every key press steps one axis by 0.1 (held keys repeat); the values stay until changed.

Drone: w/s throttle (climb/descend), i/k pitch (forward/back), j/l roll (left/right), a/d yaw
(left/right), space: all sticks to zero (hover). Car: w/s throttle (negative = reverse), a/d
steering (left/right), b/n brake up/down, space: throttle 0 and full brake. q quits.
"""

from __future__ import annotations

import os
import select
import sys
import time
from typing import Any

import numpy as np

STEP = 0.1
RATE_HZ = 20.0

# key -> (axis index, step) per layout
DRONE_KEYS = {"w": (0, STEP), "s": (0, -STEP), "i": (1, STEP), "k": (1, -STEP), "l": (2, STEP), "j": (2, -STEP),
              "a": (3, STEP), "d": (3, -STEP)}
CAR_KEYS = {"w": (0, STEP), "s": (0, -STEP), "n": (1, -STEP), "b": (1, STEP), "a": (2, STEP), "d": (2, -STEP)}
LIMITS = {"drone": [(-1, 1)] * 4, "car": [(-1, 1), (0, 1), (-1, 1)]}
NAMES = {"drone": ("throttle", "pitch", "roll", "yaw"), "car": ("throttle", "brake", "steering")}


def apply_key(layout: str, values: np.ndarray, key: str) -> np.ndarray:
    """The stick values after one key press (pure function; unknown keys change nothing)."""
    out = values.copy()
    if key == " ":
        out[:] = 0.0
        if layout == "car":
            out[1] = 1.0                    # stop: full brake
        return out
    table = DRONE_KEYS if layout == "drone" else CAR_KEYS
    if key in table:
        axis, step = table[key]
        lo, hi = LIMITS[layout][axis]
        out[axis] = float(np.clip(round(out[axis] + step, 3), lo, hi))
    return out


def run_teleop(vehicle: str, layout: str, stdin: Any = None, stdout: Any = None) -> int:
    """Read keys from the terminal and publish until ``q``; returns an exit code."""
    import termios
    import tty

    from .sensors.messages import msg_type
    from .transport.ros2.dds_backend import DdsPublisher

    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout
    if not stdin.isatty():
        print("error: teleop reads keys from a terminal (stdin is not a TTY)", file=sys.stderr)
        return 2
    publisher = DdsPublisher()
    Array = msg_type("std_msgs/msg/Float32MultiArray")
    layout_msg = msg_type("std_msgs/msg/MultiArrayLayout")(dim=[], data_offset=0)
    values = np.zeros(len(LIMITS[layout]), dtype=np.float32)
    if layout == "car":
        values[1] = 1.0
    topic = f"/{vehicle}/teleop"
    fd = stdin.fileno()
    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)
        stdout.write(f"teleop {vehicle} ({layout}) on {topic}; q quits\r\n")
        next_send = time.monotonic()
        while True:
            ready, _, _ = select.select([fd], [], [], max(0.0, next_send - time.monotonic()))
            if ready:
                key = os.read(fd, 1).decode(errors="ignore").lower()
                if key == "q":
                    break
                values = apply_key(layout, values, key).astype(np.float32)
                shown = "  ".join(f"{n} {v:+.1f}" for n, v in zip(NAMES[layout], values))
                stdout.write(f"\r{shown}   ")
                stdout.flush()
            if time.monotonic() >= next_send:
                publisher.publish(topic, Array(layout=layout_msg, data=values.copy()))
                next_send += 1.0 / RATE_HZ
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        publisher.close()
        stdout.write("\r\n")
    return 0


__all__ = ["CAR_KEYS", "DRONE_KEYS", "apply_key", "run_teleop"]
