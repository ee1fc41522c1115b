"""The single-drone tasks: their worlds, starts, state observations, rewards and terminations.

Every task is written for N copies at once (a single environment is a batch of one). Copy ``i`` has
its own patch of the world, ``origin = ((i - (N - 1) / 2) * spacing, 0, 0)``: far enough apart that copies never
touch, and that no copy's sensors reach another's. Rewards and terminations, per control step:

**Hover** (``unetyemu/Hover-v0``, default level ``motors``, 8 s): hold the point 2 m above the
copy's origin from a start up to 1 m (horizontally), 0.8 m (vertically) away, any heading, drifting
at up to 0.3 m/s. Reward ``max(0, 1 - d / 2 m) - 0.01 |omega|`` (``d`` the distance to the point,
``|omega|`` the body rate [rad/s]).

**Waypoints** (``unetyemu/Waypoints-v0``, default level ``velocity``, 30 s): fly through four
waypoints in order (each within 15 m horizontally of the origin, 2-8 m up). Reward: metres closed
toward the current waypoint this step, +10 for each waypoint reached (within 1 m), -0.01 a step;
the episode ends (success) at the last one.

**Delivery** (``unetyemu/Delivery-v0``, default level ``velocity`` + a gripper, 60 s): a 1 kg
package waits on the depot pad at the origin; a 12 m building stands between it and the drop pad
30 m east. The action has a fifth element, the gripper: above +0.5 it grabs (the payload bay's reach
decides), below -0.5 it lets go. Reward: metres closed toward the package (then, carrying it,
toward the point 1 m above the drop pad), +10 for the pickup, +20 for a package let go over the drop
pad (within its 1.5 m half-width, at most 1 m above it; success, the episode ends), -0.01 a step.
Letting go anywhere else drops the package: -10, the episode ends.

Every task ends an episode with -10 when the drone **crashes** (an impact, as the simulator's impact
monitor counts them, of the drone or what it carries; touching the ground; or turning upside down),
goes **out of bounds** (beyond the task's box around its copy), or its **battery** is empty; and
truncates it at the task's duration.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..systems.flight_state import PayloadRequest
from .flight_batch import FlightBatch

CRASH_PENALTY = 10.0
STEP_COST = 0.01
GROUND_CLEARANCE_M = 0.12       # the body's centre below this height: it touches the ground


@dataclass
class Outcome:
    """One control step's reward and endings for N copies."""

    reward: np.ndarray                           # (N,)
    terminated: np.ndarray                       # (N,) bool
    info: dict[str, np.ndarray] = field(default_factory=dict)   # name -> (N,) per-copy figures and flags


class DroneTask:
    """A task over N copies: subclasses give the scene, the starts, the state and the reward."""

    name = ""
    default_level = "velocity"
    episode_s = 10.0
    spacing_m = 60.0
    bounds_m = (10.0, 10.0)       # (horizontal radius, height) of the copy's box
    extra_actions = 0             # action elements beyond the four of the level (the gripper)
    state_labels: tuple[str, ...] = ()

    def __init__(self, n: int) -> None:
        self.n = n
        self.origin = np.zeros((n, 3))
        self.origin[:, 0] = self.spacing_m * (np.arange(n) - (n - 1) / 2.0)    # centred on the world's origin
        self.drones = [f"drone_{i}" for i in range(n)]
        self.prev_impacts = np.zeros(n, dtype=np.int64)

    # -- the world ---------------------------------------------------------------------------------
    def scene_yaml(self) -> str:
        size = self.spacing_m * self.n + 2.0 * self.spacing_m
        return f"scene: {{generator: none, ground_size_m: {size:g}}}\n"

    def packages_yaml(self) -> str:
        return ""

    def world_yaml(self, physics_hz: float, seed: int, sensors_yaml: str) -> str:
        lines = [f"world: {{name: rl_{self.name.lower()}, physics_hz: {physics_hz:g}, seed: {seed}}}",
                 self.scene_yaml().rstrip("\n"), self.packages_yaml().rstrip("\n"), "vehicles:"]
        comps = f", components: {{{sensors_yaml}}}" if sensors_yaml else ""
        for i, name in enumerate(self.drones):
            x, y, z = self.origin[i] + self.rest_offset_m()
            lines.append(f"  - {{name: {name}, type: quadrotor, preset: medium, "
                         f"pose: {{position_m: [{x:.3f}, {y:.3f}, {z:.3f}]}}{comps}}}")
        return "\n".join(line for line in lines if line) + "\n"

    def rest_offset_m(self) -> np.ndarray:
        """Where a drone waits in the saved state, from its copy's origin [m]."""
        return np.array([0.0, 0.0, 2.0])

    # -- episodes ----------------------------------------------------------------------------------
    def start(self, batch: FlightBatch, k: np.ndarray, rng: np.random.Generator) -> None:
        """Begin new episodes for copies ``k``: draw their goals and starts, place the bodies."""
        raise NotImplementedError

    def state(self, batch: FlightBatch) -> np.ndarray:
        """(N, len(state_labels)) float observation of every copy."""
        raise NotImplementedError

    def outcome(self, batch: FlightBatch) -> Outcome:
        """Reward and terminations of the step just taken (updates the task's per-copy progress)."""
        raise NotImplementedError

    def before_step(self, batch: FlightBatch, extra: np.ndarray) -> None:
        """Act on the action's extra elements (N, extra_actions) before the physics runs."""

    # -- shared pieces -----------------------------------------------------------------------------
    def _body_state(self, batch: FlightBatch) -> tuple[np.ndarray, ...]:
        f, r = batch.sim.fleet, batch.rows
        return f.pos_enu_m[r], f.vel_enu_m_s[r], f.quat_enu_flu_xyzw[r], f.rate_flu_rad_s[r]

    def _failures(self, batch: FlightBatch, reward: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """``(reward, failed, flags)``: the step's reward, -:data:`CRASH_PENALTY` where the copy crashed, went
        out of bounds or emptied its battery; which copies failed; and each reason, by name."""
        f, r = batch.sim.fleet, batch.rows
        impacts = self._drone_impacts(batch)
        pos = f.pos_enu_m[r]
        rel = pos - self.origin
        upside_down = f.R_enu_flu[r, 2, 2] < 0.0
        crashed = (impacts > self.prev_impacts) | (pos[:, 2] < GROUND_CLEARANCE_M) | upside_down
        out = (np.hypot(rel[:, 0], rel[:, 1]) > self.bounds_m[0]) | (rel[:, 2] > self.bounds_m[1])
        battery = f.soc_frac[r] <= 0.0
        self.prev_impacts = impacts.copy()
        failed = crashed | out | battery
        return (np.where(failed, -CRASH_PENALTY, reward), failed,
                {"crashed": crashed, "out_of_bounds": out & ~crashed, "battery_empty": battery})

    def _drone_impacts(self, batch: FlightBatch) -> np.ndarray:
        return batch.impacts()


class HoverTask(DroneTask):
    name = "Hover"
    default_level = "motors"
    episode_s = 8.0
    spacing_m = 40.0
    bounds_m = (5.0, 7.0)
    state_labels = ("goal_e_m", "goal_n_m", "goal_u_m", "v_e_m_s", "v_n_m_s", "v_u_m_s",
                    "qx", "qy", "qz", "qw", "p_rad_s", "q_rad_s", "r_rad_s",
                    "last_a0", "last_a1", "last_a2", "last_a3")

    def __init__(self, n: int) -> None:
        super().__init__(n)
        self.goal = self.origin + np.array([0.0, 0.0, 2.0])

    def start(self, batch: FlightBatch, k: np.ndarray, rng: np.random.Generator) -> None:
        m = len(k)
        pos = self.goal[k] + np.column_stack([rng.uniform(-1.0, 1.0, (m, 2)), rng.uniform(-0.8, 0.8, m)])
        vel = rng.uniform(-0.3, 0.3, (m, 3))
        batch.place(k, pos, rng.uniform(-np.pi, np.pi, m), vel)
        self.prev_impacts[k] = batch.impacts()[k]

    def state(self, batch: FlightBatch) -> np.ndarray:
        pos, vel, quat, rate = self._body_state(batch)
        return np.hstack([self.goal - pos, vel, quat, rate, batch.last_action[:, :4]])

    def outcome(self, batch: FlightBatch) -> Outcome:
        pos, _vel, _quat, rate = self._body_state(batch)
        dist = np.linalg.norm(self.goal - pos, axis=1)
        reward = np.maximum(0.0, 1.0 - dist / 2.0) - 0.01 * np.linalg.norm(rate, axis=1)
        reward, failed, fail = self._failures(batch, reward)
        return Outcome(reward, failed, {"distance_m": dist, "is_success": np.zeros(self.n, dtype=bool), **fail})


class WaypointsTask(DroneTask):
    name = "Waypoints"
    default_level = "velocity"
    episode_s = 30.0
    spacing_m = 100.0
    bounds_m = (30.0, 15.0)
    count = 4
    reach_m = 1.0
    state_labels = ("wp_e_m", "wp_n_m", "wp_u_m", "next_e_m", "next_n_m", "next_u_m",
                    "v_e_m_s", "v_n_m_s", "v_u_m_s", "qx", "qy", "qz", "qw", "p_rad_s", "q_rad_s", "r_rad_s",
                    "done_frac", "last_a0", "last_a1", "last_a2", "last_a3")

    def __init__(self, n: int) -> None:
        super().__init__(n)
        self.waypoints = np.zeros((n, self.count, 3))
        self.index = np.zeros(n, dtype=np.intp)
        self.prev_dist = np.zeros(n)

    def start(self, batch: FlightBatch, k: np.ndarray, rng: np.random.Generator) -> None:
        m = len(k)
        offsets = np.concatenate([rng.uniform(-15.0, 15.0, (m, self.count, 2)), rng.uniform(2.0, 8.0, (m, self.count, 1))],
                                 axis=2)
        self.waypoints[k] = self.origin[k][:, None, :] + offsets
        self.index[k] = 0
        start = self.origin[k] + self.rest_offset_m()
        batch.place(k, start, rng.uniform(-np.pi, np.pi, m))
        self.prev_dist[k] = np.linalg.norm(self.waypoints[k, 0] - start, axis=1)
        self.prev_impacts[k] = batch.impacts()[k]

    def _current(self) -> tuple[np.ndarray, np.ndarray]:
        i = np.minimum(self.index, self.count - 1)
        nxt = np.minimum(self.index + 1, self.count - 1)
        rows = np.arange(self.n)
        return self.waypoints[rows, i], self.waypoints[rows, nxt]

    def state(self, batch: FlightBatch) -> np.ndarray:
        pos, vel, quat, rate = self._body_state(batch)
        wp, nxt = self._current()
        return np.hstack([wp - pos, nxt - pos, vel, quat, rate, (self.index / self.count)[:, None],
                          batch.last_action[:, :4]])

    def outcome(self, batch: FlightBatch) -> Outcome:
        pos = batch.sim.fleet.pos_enu_m[batch.rows]
        wp, _ = self._current()
        dist = np.linalg.norm(wp - pos, axis=1)
        reward = (self.prev_dist - dist) - STEP_COST
        reached = dist < self.reach_m
        reward = reward + 10.0 * reached
        self.index = self.index + reached
        success = self.index >= self.count
        wp_new, _ = self._current()
        self.prev_dist = np.where(reached, np.linalg.norm(wp_new - pos, axis=1), dist)
        reward, failed, fail = self._failures(batch, reward)
        return Outcome(reward, failed | success, {"distance_m": dist, "waypoints_reached": self.index.copy(),
                                                   "is_success": success & ~failed, **fail})


class DeliveryTask(DroneTask):
    name = "Delivery"
    default_level = "velocity"
    episode_s = 60.0
    spacing_m = 150.0
    bounds_m = (50.0, 30.0)
    extra_actions = 1
    drop_offset_m = np.array([30.0, 0.0, 0.0])
    pad_half_m = 1.5
    package_kg = 1.0
    package_size_m = 0.3
    state_labels = ("pkg_e_m", "pkg_n_m", "pkg_u_m", "drop_e_m", "drop_n_m", "drop_u_m", "carrying",
                    "v_e_m_s", "v_n_m_s", "v_u_m_s", "qx", "qy", "qz", "qw", "p_rad_s", "q_rad_s", "r_rad_s",
                    "soc", "last_a0", "last_a1", "last_a2", "last_a3", "last_grip")

    def __init__(self, n: int) -> None:
        super().__init__(n)
        self.packages = [f"package_{i}" for i in range(n)]
        self.drop = self.origin + self.drop_offset_m
        self.drop_point = self.drop + np.array([0.0, 0.0, 1.0])     # where a drone lets go, 1 m above the pad [m]
        self.carrying = np.zeros(n, dtype=bool)
        self.picked = np.zeros(n, dtype=bool)
        self.prev_dist = np.zeros(n)
        self.last_grip = np.zeros(n)
        self._package_rest: np.ndarray | None = None      # each package's pose in the saved state [m]
        self._pkg_rows: np.ndarray | None = None
        self._pkg_impacts_seen: np.ndarray | None = None
        self._pkg_impacts_carried = np.zeros(n, dtype=np.int64)

    def scene_yaml(self) -> str:
        size = self.spacing_m * self.n + 2.0 * self.spacing_m
        pads, buildings = [], []
        for i in range(self.n):
            x0 = self.origin[i, 0]
            pads.append(f"{{name: depot_{i}, position_m: [{x0:.1f}, 0.0], size_m: 3.0, kind: start}}")
            pads.append(f"{{name: drop_{i}, position_m: [{x0 + self.drop_offset_m[0]:.1f}, 0.0], size_m: 3.0}}")
            buildings.append(f"{{name: block_{i}, center_m: [{x0 + 15.0:.1f}, 0.0], size_m: [6.0, 30.0], "
                             f"height_m: 12.0}}")
        return (f"scene:\n  generator: none\n  ground_size_m: {size:g}\n  pads: [{', '.join(pads)}]\n"
                f"  buildings: [{', '.join(buildings)}]\n")

    def packages_yaml(self) -> str:
        lines = ["packages:"]
        s = self.package_size_m
        for i, name in enumerate(self.packages):
            lines.append(f"  - {{name: {name}, mass_kg: {self.package_kg:g}, size_m: [{s:g}, {s:g}, {s:g}], "
                         f"pose: {{pad: depot_{i}}}}}")
        return "\n".join(lines) + "\n"

    def rest_offset_m(self) -> np.ndarray:
        return np.array([-3.0, 0.0, 2.0])

    def _package_rows(self, batch: FlightBatch) -> np.ndarray:
        if self._pkg_rows is None:                         # the packages' fleet rows never change
            self._pkg_rows = np.array([batch.sim.row(p) for p in self.packages], dtype=np.intp)
        return self._pkg_rows

    def _package_pos(self, batch: FlightBatch) -> np.ndarray:
        return batch.sim.fleet.pos_enu_m[self._package_rows(batch)]

    def _grab_point(self, batch: FlightBatch) -> np.ndarray:
        """Where the drone's centre is when the package is within its reach (just above the package)."""
        return self._package_pos(batch) + np.array([0.0, 0.0, self.package_size_m / 2.0 + 0.25])

    def start(self, batch: FlightBatch, k: np.ndarray, rng: np.random.Generator) -> None:
        m = len(k)
        if self._package_rest is None:
            self._package_rest = self._package_pos(batch)
        pos = self.origin[k] + self.rest_offset_m() + np.column_stack([rng.uniform(-1.0, 1.0, (m, 2)),
                                                                        rng.uniform(-0.5, 0.5, m)])
        batch.place(k, pos, rng.uniform(-np.pi, np.pi, m))
        # the packages after place() let go of them
        batch.place_bodies([self.packages[i] for i in np.asarray(k).tolist()], self._package_rest[k])
        self.carrying[k] = False
        self.picked[k] = False
        self.last_grip[k] = 0.0
        self.prev_dist[k] = np.linalg.norm(self._grab_point(batch)[k] - pos, axis=1)
        self.prev_impacts[k] = self._drone_impacts(batch)[k]

    def before_step(self, batch: FlightBatch, extra: np.ndarray) -> None:
        grip = np.clip(np.nan_to_num(np.asarray(extra, dtype=float).reshape(self.n)), -1.0, 1.0)
        self.last_grip = grip
        f, r = batch.sim.fleet, batch.rows
        carrying = f.payload_entity[r] >= 0
        for i in np.flatnonzero((grip > 0.5) & ~carrying).tolist():
            f.payload_package[r[i]] = self.packages[i]
            f.payload_request[r[i]] = PayloadRequest.ATTACH
        for i in np.flatnonzero((grip < -0.5) & carrying).tolist():
            f.payload_request[r[i]] = PayloadRequest.RELEASE

    def _drone_impacts(self, batch: FlightBatch) -> np.ndarray:
        f = batch.sim.fleet
        pkg_rows = self._package_rows(batch)
        # the drone's impacts plus those of the package while it carries it (a carried package that hits a
        # wall is the drone's crash; one hit while it lies on the ground or falls is not)
        seen = self._pkg_impacts_seen if self._pkg_impacts_seen is not None else f.impacts[pkg_rows]
        self._pkg_impacts_carried += np.where(self.carrying, f.impacts[pkg_rows] - seen, 0)
        self._pkg_impacts_seen = f.impacts[pkg_rows].copy()
        return batch.impacts() + self._pkg_impacts_carried

    def state(self, batch: FlightBatch) -> np.ndarray:
        pos, vel, quat, rate = self._body_state(batch)
        f = batch.sim.fleet
        return np.hstack([self._grab_point(batch) - pos, self.drop_point - pos,
                          self.carrying[:, None].astype(float), vel, quat, rate, f.soc_frac[batch.rows][:, None],
                          batch.last_action[:, :4], self.last_grip[:, None]])

    def outcome(self, batch: FlightBatch) -> Outcome:
        f, r = batch.sim.fleet, batch.rows
        pos = f.pos_enu_m[r]
        carrying_now = f.payload_entity[r] >= 0
        picked_up = carrying_now & ~self.carrying
        let_go = self.carrying & ~carrying_now
        pkg = self._package_pos(batch)
        over_pad = (np.hypot(*(pkg - self.drop)[:, :2].T) <= self.pad_half_m) & \
                   (pkg[:, 2] - self.package_size_m / 2.0 - self.drop[:, 2] <= 1.0)
        delivered = let_go & over_pad
        dropped = let_go & ~over_pad
        self.carrying = carrying_now
        self.picked |= picked_up
        goal = np.where(carrying_now[:, None] | self.picked[:, None], self.drop_point,
                        self._grab_point(batch))
        dist = np.linalg.norm(goal - pos, axis=1)
        progress = np.where(picked_up | let_go, 0.0, self.prev_dist - dist)
        self.prev_dist = dist
        reward = progress - STEP_COST + 10.0 * picked_up + 20.0 * delivered - CRASH_PENALTY * dropped
        reward, failed, fail = self._failures(batch, reward)
        return Outcome(reward, failed | delivered | dropped,
                       {"distance_m": dist, "carrying": carrying_now.copy(), "package_dropped": dropped & ~failed,
                        "is_success": delivered & ~failed, **fail})


TASKS: dict[str, type[DroneTask]] = {"hover": HoverTask, "waypoints": WaypointsTask, "delivery": DeliveryTask}

__all__ = ["CRASH_PENALTY", "DeliveryTask", "DroneTask", "HoverTask", "Outcome", "TASKS", "WaypointsTask"]
