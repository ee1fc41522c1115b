"""Physical and computational limits of everything read from a world or mission file.

Every number read from outside gets a range here or next to its field, each with its reason, so that a
value that validates can also be simulated: no overflow, no NaN, no allocation that cannot fit in
memory, no run that never ends. The type aliases below are used by the schema dataclasses
(``Annotated`` markers checked by :func:`unetyemu_ecs.config.schema.convert`).
"""

from __future__ import annotations

from typing import Annotated

from .schema import Ge, Le, MaxLen, NonEmpty

# --- input text ------------------------------------------------------------------------------------
# A world file with a 16 x 16 city, a few hundred explicit objects and a few missions is ~50 kB; 1 MiB
# leaves 20x headroom and keeps parsing to about a second (libyaml) or ten (pure-Python YAML).
MAX_WORLD_FILE_BYTES = 1 << 20
# A mission of MAX_MISSION_STEPS pretty-printed steps is ~300 kB.
MAX_MISSION_TEXT_BYTES = 1 << 20
# Nodes of the parsed document *after* alias expansion: 200 000 nodes are ~50 MB of Python objects.
# Anchors and aliases stay usable for shared blocks; an alias bomb stops at this count.
MAX_WORLD_NODES = 200_000
MAX_MISSION_NODES = 50_000
# A world nests ~9 levels (vehicles[i].components.mission.steps[j].waypoints[k].x); Python's
# recursion limit (1000) is far away at 32.
MAX_WORLD_NESTING = 32
MAX_MISSION_NESTING = 16    # our mission format nests 5 deep (mission, steps, step, waypoints, waypoint)

# --- names -----------------------------------------------------------------------------------------
# Names become ROS 2 topic prefixes, frame ids, CSV columns and file names: 64 characters keeps every
# derived topic (/name/depth/camera_info...) well inside ROS 2's 255-character topic name limit.
MAX_NAME_LEN = 64
Name = Annotated[str, NonEmpty(), MaxLen(MAX_NAME_LEN)]
# A full ROS 2 topic or frame name (rmw limits topic names to 255 characters).
MAX_TOPIC_LEN = 255

# --- space -----------------------------------------------------------------------------------------
# The world frame is a flat ENU plane around the geodetic origin: within 20 km the flat-Earth error of
# the GPS conversion stays below ~30 m of curvature drop and the float32 geometry of the ray caster
# keeps millimetre resolution (float32 spacing at 20 km is 2 mm).
MAX_XY_M = 20_000.0
# Heights: from 100 m below the ground plane (a quarry, a tunnel) to 10 km (above every drone's
# service ceiling; airliners cruise at ~11 km).
MIN_Z_M = -100.0
MAX_Z_M = 10_000.0
XM = Annotated[float, Ge(-MAX_XY_M), Le(MAX_XY_M)]          # east or north coordinate [m]
ZM = Annotated[float, Ge(MIN_Z_M), Le(MAX_Z_M)]              # height [m]
XY = tuple[XM, XM]
XYZ = tuple[XM, XM, ZM]
# An angle in degrees: a turn either way; a larger number is a typo, not an angle.
Deg = Annotated[float, Ge(-360.0), Le(360.0)]
# Offsets of a body on a pad or parking spot, and sensor mounts on a vehicle: within 50 m / 10 m.
MAX_OFFSET_M = 50.0
MAX_MOUNT_M = 10.0

# --- time ------------------------------------------------------------------------------------------
# Physics below 50 Hz (20 ms steps) makes contacts and the 240 Hz-tuned rate loops unstable; above
# 10 kHz nothing gets more accurate, only slower.
MIN_PHYSICS_HZ = 50.0
MAX_PHYSICS_HZ = 10_000.0
# One week of simulated time: longer is a typo (at 240 Hz it is already 145 M steps).
MAX_DURATION_S = 7 * 24 * 3600.0
# Waits of a mission step and teleop key frame times: within a day / a week.
MAX_WAIT_S = 24 * 3600.0

# --- counts ----------------------------------------------------------------------------------------
# Every vehicle is a PyBullet body with its own control stack and sensors; the stress benchmark flies 1000
# (benchmarks/stress.py), which 2000 leaves room above.
MAX_VEHICLES = 2000
MAX_PACKAGES = 1024
# Static scene objects (generated + explicit): a 16 x 16 city is ~8 500 objects and takes seconds
# to build; 20 000 keeps building the physics and the ray-cast mesh within a minute and ~1 GB.
MAX_SCENE_OBJECTS = 20_000
MAX_MISSION_STEPS = 1_000       # a mission of 1000 steps already flies for hours
MAX_WAYPOINTS = 1_000           # per mission step or car route
MAX_KEYFRAMES = 10_000          # teleop script key frames

__all__ = [
    "MAX_DURATION_S", "MAX_KEYFRAMES", "MAX_MISSION_NESTING", "MAX_MISSION_NODES", "MAX_MISSION_STEPS",
    "MAX_MISSION_TEXT_BYTES", "MAX_MOUNT_M", "MAX_NAME_LEN", "MAX_OFFSET_M", "MAX_PACKAGES", "MAX_PHYSICS_HZ",
    "MAX_SCENE_OBJECTS", "MAX_TOPIC_LEN", "MAX_VEHICLES", "MAX_WAIT_S", "MAX_WAYPOINTS", "MAX_WORLD_FILE_BYTES",
    "MAX_WORLD_NESTING", "MAX_WORLD_NODES", "MAX_XY_M", "MAX_Z_M", "MIN_PHYSICS_HZ", "MIN_Z_M", "XY", "XYZ",
    "Deg", "Name", "XM", "ZM",
]

# --- sensors ---------------------------------------------------------------------------------------
# A sensor samples at most once per physics step (10 kHz at most) and at least once per 100 s.
SensorRate = Annotated[float, Ge(0.01), Le(MAX_PHYSICS_HZ)]
