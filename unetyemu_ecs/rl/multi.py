"""Drones and cars in one small city, each flown or driven by its own agent: a PettingZoo ``ParallelEnv``.

Every agent is a vehicle of one :class:`~unetyemu_ecs.app.Simulation` (a :class:`~.flight_batch.FlightBatch`
built once): the agents share the world, and what they run into is real, PyBullet bodies colliding and
the simulator's impact monitor counting it. Each agent has a goal, drawn per episode from the
environment's seeded RNG: a drone's is 10-30 m above a street, a car's on a street in a lane.

::

    from unetyemu_ecs.rl.multi import CityParallelEnv

    env = CityParallelEnv(n_drones=3, n_cars=2)
    obs, infos = env.reset(seed=0)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)

Actions (float32 Boxes in [-1, 1], NaN counts as 0, beyond +-1 is clipped):

- a drone (``drone_i``, shape (4,)): the ``velocity`` level of :mod:`.actions`: east and north velocity
  (the pair clipped to the unit circle) at up to the drone's cruise speed, up velocity at up to its
  climb (down: descent) limit, yaw rate at up to its yaw-rate limit;
- a car (``car_i``, shape (2,)): forward speed ``a0 * CAR_MAX_SPEED_M_S`` (negative: reverse) and yaw
  rate ``a1 * CAR_MAX_YAW_RATE_RAD_S`` (CCW positive), held by the car's own speed and steering control
  (its steering limit still shrinks with speed).

Observations (float32 Boxes; every element's name and unit: :data:`DRONE_OBS_LABELS`, :data:`CAR_OBS_LABELS`):

=========== ==== ================================================================================
agent       size elements
=========== ==== ================================================================================
drone       19   goal - position, ENU [m] (3); velocity, ENU [m/s] (3); attitude quaternion of body FLU
                 in ENU, xyzw (4); body rates, FLU [rad/s] (3); nearest other vehicle's position -
                 own, ENU [m] (3); its velocity - own, ENU [m/s] (3)
car         15   goal - position, ENU [m] (3; the goal is at the car's own height, so z is ~0); velocity,
                 ENU [m/s] (3); heading cos, sin (2, yaw CCW from east); yaw rate [rad/s] (1); nearest
                 other vehicle's position - own, ENU [m] (3); its velocity - own, ENU [m/s] (3)
=========== ==== ================================================================================

Each is clipped to its Box (positions within +-1000 m, speeds +-60 m/s, rates +-100 rad/s). "Nearest
other vehicle": the nearest (3D distance) of every other agent's vehicle, those whose episode
ended too (they stay where they stopped, obstacles still); with a single vehicle both parts are zero.

Rewards per control step: the metres closed toward the goal (a drone's 3D distance, a car's horizontal)
minus :data:`TIME_PENALTY` (per step); +:data:`GOAL_REWARD` on reaching it (a drone within
:data:`DRONE_GOAL_RADIUS_M`, a car within :data:`CAR_GOAL_RADIUS_M`); -:data:`IMPACT_PENALTY` for a new
impact (the simulator's impact monitor: a new contact at >= 2 m/s relative speed with anything, another
agent, a building, a tree, a kerb, the ground) and for leaving the city (outside the layout's x/y extent,
or a drone above ``ceiling_m``). Each of these ends that agent's episode (terminated), as does a
drone's battery running empty (``soc_frac <= 0``, no penalty); every agent still going is truncated
after ``max_episode_s``. An agent whose episode ended leaves :attr:`agents` and its vehicle is stopped
(a drone holds where it is: zero velocity action; a car brakes to a stop: zero speed command).

``info[agent]``: ``distance_m`` (to its goal [m]), ``reason`` (``""`` while going, else ``"goal"``,
``"impact"``, ``"out_of_bounds"``, ``"battery_empty"`` or ``"time_limit"``) and ``hit`` (on an impact,
the name of what it hit first: a vehicle or a scene object such as ``building_3`` or ``the ground``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as p
from gymnasium import logger, spaces
from pettingzoo import ParallelEnv

from ..app import SimulationClosedError
from ..frames import yaw_rad_from_quat_xyzw
from ..scene.primitives import Box, SceneClass
from ..systems.car_state import DriveMode, set_path
from .flight_batch import FlightBatch
from .observations import bounds_by_unit

CONTROL_HZ = 30.0                 # actions per simulated second
PHYSICS_HZ = 240                  # physics steps per simulated second (8 per action)
CAR_MAX_SPEED_M_S = 10.0          # forward speed of a full car action (36 km/h, a city street's limit)
CAR_MAX_YAW_RATE_RAD_S = 0.5      # yaw rate of a full car action: a 20 m radius turn at 10 m/s (2.5 m/s^2
                                  # lateral), a street corner at a crawl
DRONE_GOAL_ALT_M = (10.0, 30.0)   # a drone's goal and start: this high above a street [m] (above the trees)
DRONE_GOAL_RADIUS_M = 2.0         # a drone reaches its goal within this 3D distance [m]
CAR_GOAL_RADIUS_M = 4.0           # a car reaches its goal within this horizontal distance [m] (a car length)
MIN_GOAL_DISTANCE_M = 20.0        # a sampled goal is at least this far from the agent's start [m]
MIN_START_SEPARATION_M = 8.0      # sampled starts are at least this far apart [m]
STREET_MARGIN_M = 8.0             # sampled points keep this far from a street segment's ends [m]
GOAL_REWARD = 10.0
IMPACT_PENALTY = 10.0             # a new impact, or leaving the city
TIME_PENALTY = 0.01               # per control step
MAX_OBS_M = 1000.0                # bounds of the observation's positions [m] (speeds, rates: observations.py)
_SAMPLE_TRIES = 200

_NEAREST = ("nearest_dx_m", "nearest_dy_m", "nearest_dz_m", "nearest_dvx_m_s", "nearest_dvy_m_s", "nearest_dvz_m_s")
DRONE_OBS_LABELS = ("goal_dx_m", "goal_dy_m", "goal_dz_m", "vx_m_s", "vy_m_s", "vz_m_s",
                    "qx", "qy", "qz", "qw", "p_rad_s", "q_rad_s", "r_rad_s", *_NEAREST)
CAR_OBS_LABELS = ("goal_dx_m", "goal_dy_m", "goal_dz_m", "vx_m_s", "vy_m_s", "vz_m_s",
                  "cos_yaw", "sin_yaw", "yaw_rate_rad_s", *_NEAREST)


def city_world_text(n_drones: int, n_cars: int, *, blocks: tuple[int, int] = (2, 2), city_seed: int = 7,
                    drone_preset: str = "small", car_preset: str = "medium") -> str:
    """The world file (YAML) of the environment: a ``blocks`` street-grid city (60 m blocks, 12 m
    streets, buildings 8-40 m) with ``drone_i`` on the depot's start pads and ``car_i`` on parking
    spots (where they rest in the saved state; every episode places them anew)."""
    vehicles = [f"  - {{name: drone_{i}, type: quadrotor, preset: {drone_preset}, pose: {{pad: start_{i + 1}}}}}"
                for i in range(n_drones)]
    vehicles += [f"  - {{name: car_{i}, type: car, preset: {car_preset}, pose: {{parking: parking_{i + 1}}}}}"
                 for i in range(n_cars)]
    return "\n".join([
        f"world: {{name: city_agents, physics_hz: {PHYSICS_HZ}, seed: {int(city_seed)}}}",
        "scene:",
        "  generator: urban",
        f"  urban: {{blocks_x: {blocks[0]}, blocks_y: {blocks[1]}, block_size_m: 60, street_width_m: 12,",
        f"          building_height_m: [8, 40], start_pads: {max(n_drones, 1)}, target_pads: 0, roof_pads: 0,",
        f"          parking_spots: {max(n_cars, 1)}}}",
        "vehicles:", *vehicles, ""])


# -- the streets -------------------------------------------------------------------------------------
def street_segments(layout: Any) -> np.ndarray:
    """Every road box of the layout as a street segment, (S, 6) float64: centre x, y [m], unit direction
    along the street x, y, half length along, half width across [m] (the generated streets are boxes
    aligned with the axes; the long side is the street's direction)."""
    rows = []
    for obj in layout.objects:
        if obj.cls != SceneClass.ROAD:
            continue
        for shape in obj.shapes:
            if not isinstance(shape, Box):
                continue
            hx, hy = float(shape.half_extents_m[0]), float(shape.half_extents_m[1])
            c, s = math.cos(shape.yaw_rad), math.sin(shape.yaw_rad)
            along = (c, s) if hx >= hy else (-s, c)
            rows.append((shape.center_enu_m[0], shape.center_enu_m[1], *along, max(hx, hy), min(hx, hy)))
    if not rows:
        raise ValueError("the city has no streets to place agents on")
    return np.array(rows, dtype=float)


def sample_street_point(rng: np.random.Generator, streets: np.ndarray, lane: bool) -> tuple[np.ndarray, float]:
    """A point on a street, ENU x, y [m], and a heading along it [rad, CCW from east]. ``lane``: on the
    centre line of a right-hand traffic lane (a quarter of the width from the middle), facing the lane's
    direction; else anywhere across the street but 2 m from its edges, facing either way along it.
    Segments are drawn in proportion to their length, :data:`STREET_MARGIN_M` kept from their ends."""
    length = np.maximum(streets[:, 4] - STREET_MARGIN_M, 0.1)
    k = int(rng.choice(len(streets), p=length / length.sum()))
    cx, cy, ux, uy, half_len, half_w = streets[k]
    along = rng.uniform(-1.0, 1.0) * max(half_len - STREET_MARGIN_M, 0.0)
    forward = 1.0 if rng.random() < 0.5 else -1.0
    # right-hand traffic: driving along +u, the lane is on the right of the centre line (-left normal)
    across = -forward * 0.5 * half_w if lane else rng.uniform(-1.0, 1.0) * max(half_w - 2.0, 0.0)
    nx, ny = -uy, ux                                    # left normal of +u
    xy = np.array([cx + along * ux + across * nx, cy + along * uy + across * ny])
    return xy, math.atan2(forward * uy, forward * ux)


# -- the observation ---------------------------------------------------------------------------------
def nearest_others(pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of N vehicles, the nearest other one's position and velocity relative to its own
    ((N, 3) [m], (N, 3) [m/s], ENU); zeros when there is no other."""
    n = pos.shape[0]
    if n < 2:
        return np.zeros_like(pos), np.zeros_like(vel)
    dist = np.linalg.norm(pos[None, :, :] - pos[:, None, :], axis=2)
    np.fill_diagonal(dist, np.inf)
    j = np.argmin(dist, axis=1)
    return pos[j] - pos, vel[j] - vel


def _what_was_hit(events: list[tuple[float, str, str]], name: str) -> str:
    """The other side of ``name``'s first impact among ``events`` ("" if none names it). The monitor tells
    an impact from the faster side: ``(t, faster, "impact with <other> at ...")``."""
    for _, vehicle, text in events:
        if not text.startswith("impact with "):
            continue
        other = text[len("impact with "):].split(" at ", 1)[0]
        if vehicle == name:
            return other
        if other == name:
            return vehicle
    return ""


class CityParallelEnv(ParallelEnv):
    """``n_drones`` drones (``drone_0``...) and ``n_cars`` cars (``car_0``...) in one small city, one agent
    each (see the module's docstring for actions, observations and rewards).

    Parameters
    ----------
    n_drones, n_cars : how many of each (0-16 each, at least one agent)
    render_mode : None or ``"rgb_array"`` (:meth:`render` returns a top-down (H, W, 3) uint8 frame)
    max_episode_s : simulated seconds after which every agent still going is truncated [s]
    blocks : the city's blocks east x north (1-4 each; 60 m blocks, 12 m streets)
    city_seed : the seed that generates the city (its buildings; the same for every episode)
    drone_preset, car_preset : the vehicles' presets (``small``, ``medium``, ``large``; ``medium``, ``truck``)
    drone_max_speed_m_s : horizontal speed of a full drone action [m/s] (None: each drone's cruise speed)
    ceiling_m : a drone above this height leaves the city [m]
    render_size_px : edge of the square rgb_array frame [px]

    ``reset(seed, options)``: ``options["starts"]`` ``{agent: [x, y, z, yaw_rad]}`` and ``options["goals"]``
    ``{agent: [x, y, z]}`` (ENU [m]) replace the sampled start poses and goals of those agents (a car
    stands on the road at its ride height whatever z says; its goal is taken at that height too).
    """

    metadata = {"name": "unetyemu_city_v0", "render_modes": ["rgb_array"], "is_parallelizable": True,
                "render_fps": CONTROL_HZ}

    def __init__(self, n_drones: int = 3, n_cars: int = 2, *, render_mode: str | None = None,
                 max_episode_s: float = 60.0, blocks: tuple[int, int] = (2, 2), city_seed: int = 7,
                 drone_preset: str = "small", car_preset: str = "medium",
                 drone_max_speed_m_s: float | None = None, ceiling_m: float = 50.0,
                 render_size_px: int = 256) -> None:
        _check_counts(n_drones, n_cars)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if not (isinstance(max_episode_s, (int, float)) and 0.0 < max_episode_s <= 3600.0):
            raise ValueError(f"max_episode_s must be in (0, 3600] s, got {max_episode_s!r}")
        if not (isinstance(ceiling_m, (int, float)) and DRONE_GOAL_ALT_M[1] < ceiling_m <= 1000.0):
            raise ValueError(f"ceiling_m must be in ({DRONE_GOAL_ALT_M[1]:g}, 1000] m, got {ceiling_m!r}")
        if len(blocks) != 2 or not all(isinstance(b, int) and 1 <= b <= 4 for b in blocks):
            raise ValueError(f"blocks must be two integers in [1, 4], got {blocks!r}")
        if drone_max_speed_m_s is not None and not (isinstance(drone_max_speed_m_s, (int, float))
                                                    and 0.1 <= drone_max_speed_m_s <= 30.0):
            raise ValueError(f"drone_max_speed_m_s must be None or in [0.1, 30] m/s, got {drone_max_speed_m_s!r}")
        if isinstance(render_size_px, bool) or not isinstance(render_size_px, int) or not 16 <= render_size_px <= 2048:
            raise ValueError(f"render_size_px must be an integer in [16, 2048], got {render_size_px!r}")
        self.render_mode = render_mode
        self.render_size_px = render_size_px
        self.ceiling_m = float(ceiling_m)
        self._max_steps = max(1, int(round(max_episode_s * CONTROL_HZ)))
        self.drones = [f"drone_{i}" for i in range(n_drones)]
        self.cars = [f"car_{i}" for i in range(n_cars)]
        self.possible_agents = self.drones + self.cars
        self.agents: list[str] = []
        text = city_world_text(n_drones, n_cars, blocks=tuple(blocks), city_seed=city_seed,
                               drone_preset=drone_preset, car_preset=car_preset)
        self._batch = FlightBatch(text, self.drones, "velocity", CONTROL_HZ, max_speed_m_s=drone_max_speed_m_s,
                                  file="<CityParallelEnv>")
        self._closed = False
        try:
            self._setup()
        except BaseException:
            self.close()
            raise

    def _setup(self) -> None:
        """What the environment keeps of the built world: rows, heights, streets, bounds, spaces."""
        sim = self._batch.sim
        n_drones = len(self.drones)
        self._rows = np.array([sim.row(a) for a in self.possible_agents], dtype=np.intp)
        self._car_rows = self._rows[n_drones:]
        self._is_drone = np.arange(len(self.possible_agents)) < n_drones
        self._car_z_m = np.array([sim.position_enu_m(c)[2] for c in self.cars])   # ride height on the road [m]
        self._streets = street_segments(sim.layout)
        self._lo_m, self._hi_m = sim.layout.extent_min_m.copy(), sim.layout.extent_max_m.copy()
        self._radius_m = np.where(self._is_drone, DRONE_GOAL_RADIUS_M, CAR_GOAL_RADIUS_M)
        drone_lo, drone_hi = bounds_by_unit(DRONE_OBS_LABELS, MAX_OBS_M)
        car_lo, car_hi = bounds_by_unit(CAR_OBS_LABELS, MAX_OBS_M)
        self.observation_spaces = {a: spaces.Box(drone_lo, drone_hi, dtype=np.float32) for a in self.drones}
        self.observation_spaces |= {a: spaces.Box(car_lo, car_hi, dtype=np.float32) for a in self.cars}
        self.action_spaces = {a: spaces.Box(-1.0, 1.0, (4,), dtype=np.float32) for a in self.drones}
        self.action_spaces |= {a: spaces.Box(-1.0, 1.0, (2,), dtype=np.float32) for a in self.cars}
        n = len(self.possible_agents)
        self._goal = np.zeros((n, 3))
        self._live = np.zeros(n, dtype=bool)
        self._dist = np.zeros(n)
        self._impacts = np.zeros(n, dtype=np.int64)
        self._steps = 0
        self._was_reset = False
        self._events_seen = 0
        self._rng = np.random.default_rng()
        self._camera = self._camera_matrices()

    # -- PettingZoo ----------------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self.action_spaces[agent]

    @property
    def sim(self) -> Any:
        """The :class:`~unetyemu_ecs.app.Simulation` the agents live in (events, positions, layout)."""
        return self._batch.sim

    @property
    def goals(self) -> dict[str, np.ndarray]:
        """Each agent's goal this episode, ENU [m] (copies)."""
        return {a: self._goal[i].copy() for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Everything back to the state saved when the city was built (never rebuilt), then every agent
        at a new start with a new goal, both drawn from the environment's RNG (reseeded by ``seed``)."""
        self._require_open()
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        batch, sim = self._batch, self._batch.sim
        batch.restore(int(self._rng.integers(2**31)))
        starts, self._goal = self._sample_episode(self._rng)
        _apply_options(options, self.possible_agents, starts, self._goal)
        self._goal[~self._is_drone, 2] = self._car_z_m
        nd = len(self.drones)
        if nd:
            batch.place(np.arange(nd), starts[:nd, :3], starts[:nd, 3])
        if self.cars:
            batch.place_bodies(self.cars, np.column_stack([starts[nd:, :2], self._car_z_m]), starts[nd:, 3])
        self.agents = list(self.possible_agents)
        self._was_reset = True
        self._live[:] = True
        self._steps = 0
        self._impacts = sim.fleet.impacts[self._rows].astype(np.int64)
        self._events_seen = len(sim.services.events)
        self._dist = self._distances()
        obs = self._observe()
        infos = {a: self._info(i, "", "") for i, a in enumerate(self.possible_agents)}
        return {a: obs[a] for a in self.agents}, infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One control period (8 physics steps) with every live agent's action (a missing one: zero,
        the vehicle holds or stops; those of agents whose episode ended are ignored)."""
        self._require_open()
        if not self._was_reset:
            raise RuntimeError("call reset() before step()")
        if not self._live.any():
            return {}, {}, {}, {}, {}
        drone_a, car_a = self._parse(actions)
        self._batch.act(drone_a)
        self._drive_cars(car_a)
        self._batch.advance()
        self._steps += 1
        was_live = self._live.copy()
        dist = self._distances()
        reward = (self._dist - dist) - TIME_PENALTY
        self._dist = dist
        reason = self._end_reasons(dist)
        reward += np.select([reason == "impact", reason == "out_of_bounds", reason == "goal"],
                            [-IMPACT_PENALTY, -IMPACT_PENALTY, GOAL_REWARD], 0.0)
        terminated = was_live & (reason != "")
        truncated = was_live & ~terminated & (self._steps >= self._max_steps)
        reason = np.where(truncated, "time_limit", reason)
        new_events = self.sim.services.events[self._events_seen:]
        self._events_seen = len(self.sim.services.events)
        live_names = [a for i, a in enumerate(self.possible_agents) if was_live[i]]
        obs = self._observe()
        out = ({}, {}, {}, {}, {})
        for a in live_names:
            i = self.possible_agents.index(a)
            hit = _what_was_hit(new_events, a) if reason[i] == "impact" else ""
            out[0][a] = obs[a]
            out[1][a] = float(reward[i])
            out[2][a] = bool(terminated[i])
            out[3][a] = bool(truncated[i])
            out[4][a] = self._info(i, str(reason[i]), hit)
        self._live &= ~(terminated | truncated)
        self.agents = [a for i, a in enumerate(self.possible_agents) if self._live[i]]
        return out

    def render(self) -> np.ndarray | None:
        """A top-down view of the city (PyBullet's TinyRenderer, headless), (H, W, 3) uint8: north up,
        east right; each agent a filled square in its colour (drones bright, cars dark), its goal a
        hollow square of the same colour."""
        if self.render_mode is None:
            logger.warn("render() was called without a render_mode (CityParallelEnv(render_mode='rgb_array'))")
            return None
        self._require_open()
        size = self.render_size_px
        view, proj = self._camera
        _, _, rgba, _, _ = p.getCameraImage(size, size, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0,
                                            physicsClientId=self.sim.physics.id)
        img = np.reshape(np.asarray(rgba, dtype=np.uint8), (size, size, 4))[:, :, :3].copy()
        pos = self.sim.fleet.pos_enu_m[self._rows]
        for i in range(len(self.possible_agents)):
            color = _color(i, self._is_drone[i])
            _mark(img, self._pixel(pos[i]), color, filled=True)
            _mark(img, self._pixel(self._goal[i]), color, filled=False)
        return img

    def close(self) -> None:
        """Close the simulation (PyBullet disconnected); safe to call twice."""
        self._batch.close()
        self._closed = True
        self.agents = []

    def _require_open(self) -> None:
        if self._closed:
            raise SimulationClosedError("this CityParallelEnv is closed; create a new one")

    # -- episodes ------------------------------------------------------------------------------------
    def _sample_episode(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Start poses (A, 4): x, y, z [m], yaw [rad]; goals (A, 3) [m], ENU. Drones start and aim
        10-30 m above a street, cars in a lane; starts at least :data:`MIN_START_SEPARATION_M` apart,
        each goal at least :data:`MIN_GOAL_DISTANCE_M` from its start."""
        n = len(self.possible_agents)
        starts, goals = np.zeros((n, 4)), np.zeros((n, 3))
        for i in range(n):
            drone = bool(self._is_drone[i])
            for _ in range(_SAMPLE_TRIES):
                xy, yaw = sample_street_point(rng, self._streets, lane=not drone)
                z = rng.uniform(*DRONE_GOAL_ALT_M) if drone else 0.0
                start = np.array([*xy, z])
                if i == 0 or np.min(np.linalg.norm(starts[:i, :2] - start[:2], axis=1)) >= MIN_START_SEPARATION_M:
                    break
            starts[i] = (*start, rng.uniform(-math.pi, math.pi) if drone else yaw)
            for _ in range(_SAMPLE_TRIES):
                xy, _ = sample_street_point(rng, self._streets, lane=not drone)
                goal = np.array([*xy, rng.uniform(*DRONE_GOAL_ALT_M) if drone else 0.0])
                if np.linalg.norm(goal[:2] - start[:2]) >= MIN_GOAL_DISTANCE_M:
                    break
            goals[i] = goal
        return starts, goals

    # -- stepping ------------------------------------------------------------------------------------
    def _parse(self, actions: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """Drone actions (D, 4) and car actions (C, 2) in [-1, 1] (NaN -> 0, zero for agents without one)."""
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        unknown = set(actions) - set(self.possible_agents)
        if unknown:
            raise ValueError(f"actions for unknown agents {sorted(map(str, unknown))} (agents: {self.possible_agents})")
        nd = len(self.drones)
        drone_a, car_a = np.zeros((nd, 4)), np.zeros((len(self.cars), 2))
        for i, agent in enumerate(self.possible_agents):
            if not self._live[i] or agent not in actions:
                continue
            shape = self.action_spaces[agent].shape
            try:
                a = np.asarray(actions[agent], dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"the action of {agent} must be {shape} numbers in [-1, 1], "
                                 f"got {actions[agent]!r}") from None
            if a.shape != shape:
                raise ValueError(f"the action of {agent} must have shape {shape}, got shape {a.shape}")
            a = np.clip(np.nan_to_num(a, nan=0.0), -1.0, 1.0)
            if i < nd:
                drone_a[i] = a
            else:
                car_a[i - nd] = a
        return drone_a, car_a

    def _drive_cars(self, car_a: np.ndarray) -> None:
        """Speed and yaw-rate setpoints of every car (the simulator's VELOCITY drive mode, as a
        ``cmd_vel`` would set them), written straight into the fleet arrays like the drones' setpoints:
        a :meth:`Simulation.cmd_vel` per car per step would add a result to the simulation's
        append-only command log every step of training."""
        if not len(self._car_rows):
            return
        f = self.sim.fleet
        rows = self._car_rows
        f.cmd_vel[rows, 0] = car_a[:, 0] * CAR_MAX_SPEED_M_S
        f.cmd_vel[rows, 1] = car_a[:, 1] * CAR_MAX_YAW_RATE_RAD_S
        f.cmd_hold_until_s[rows] = np.inf
        for row in rows[f.drive_mode[rows] != DriveMode.VELOCITY].tolist():
            set_path(f, row, None)
            f.drive_mode[row] = DriveMode.VELOCITY

    def _distances(self) -> np.ndarray:
        """Each agent's distance to its goal [m]: a drone's 3D, a car's horizontal."""
        d = self._goal - self.sim.fleet.pos_enu_m[self._rows]
        d[~self._is_drone, 2] = 0.0
        return np.linalg.norm(d, axis=1)

    def _end_reasons(self, dist: np.ndarray) -> np.ndarray:
        """Why each live agent's episode ends this step ("" for none), in order of precedence: a new
        impact, leaving the city, an empty battery (drones), the goal reached."""
        f = self.sim.fleet
        pos = f.pos_enu_m[self._rows]
        impacts = f.impacts[self._rows].astype(np.int64)
        hit = impacts > self._impacts
        self._impacts = impacts
        outside = np.any(pos[:, :2] < self._lo_m, axis=1) | np.any(pos[:, :2] > self._hi_m, axis=1)
        outside |= self._is_drone & (pos[:, 2] > self.ceiling_m)
        empty = self._is_drone & (f.soc_frac[self._rows] <= 0.0)
        reason = np.select([hit, outside, empty, dist <= self._radius_m],
                           ["impact", "out_of_bounds", "battery_empty", "goal"], "")
        return np.where(self._live, reason, "")

    def _observe(self) -> dict[str, np.ndarray]:
        """Every agent's observation (see the module's docstring), float32, within its Box."""
        f, rows = self.sim.fleet, self._rows
        pos, vel = f.pos_enu_m[rows], f.vel_enu_m_s[rows]
        near_pos, near_vel = nearest_others(pos, vel)
        common = np.concatenate([self._goal - pos, vel], axis=1)
        quat, rates = f.quat_enu_flu_xyzw[rows], f.rate_flu_rad_s[rows]
        yaw = yaw_rad_from_quat_xyzw(quat)
        drone = np.concatenate([common, quat, rates, near_pos, near_vel], axis=1)
        car = np.concatenate([common, np.cos(yaw)[:, None], np.sin(yaw)[:, None], rates[:, 2:3], near_pos,
                              near_vel], axis=1)
        obs = {}
        for i, agent in enumerate(self.possible_agents):
            space = self.observation_spaces[agent]
            row = drone[i] if self._is_drone[i] else car[i]
            obs[agent] = np.clip(row, space.low, space.high).astype(np.float32)
        return obs

    def _info(self, i: int, reason: str, hit: str) -> dict[str, Any]:
        return {"distance_m": float(self._dist[i]), "reason": reason, "hit": hit}

    # -- rendering -----------------------------------------------------------------------------------
    def _camera_matrices(self) -> tuple[list[float], list[float]]:
        """View and projection of a camera 2 km above the city's centre with a field of view just
        covering it: perspective so slight that the frame is a map (heights shift things < 2 %)."""
        centre = 0.5 * (self._lo_m + self._hi_m)
        half = 0.5 * float(np.max(self._hi_m - self._lo_m)) + 2.0
        height = 2000.0
        fov_deg = math.degrees(2.0 * math.atan(half / height))
        view = p.computeViewMatrix([*centre, height], [*centre, 0.0], [0.0, 1.0, 0.0])
        proj = p.computeProjectionMatrixFOV(fov_deg, 1.0, height - 200.0, height + 10.0)
        return list(view), list(proj)

    def _pixel(self, point_enu_m: np.ndarray) -> tuple[int, int]:
        """(row, column) of an ENU point [m] in the rendered frame."""
        view = np.reshape(self._camera[0], (4, 4)).T            # PyBullet's matrices are column-major
        proj = np.reshape(self._camera[1], (4, 4)).T
        clip = proj @ view @ np.array([*point_enu_m, 1.0])
        ndc = clip[:2] / clip[3]
        size = self.render_size_px
        return int(round((1.0 - ndc[1]) * 0.5 * size)), int(round((ndc[0] + 1.0) * 0.5 * size))


_PALETTE = np.array([(230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48),
                     (145, 30, 180), (70, 240, 240), (240, 50, 230)], dtype=np.uint8)


def _color(i: int, drone: bool) -> np.ndarray:
    c = _PALETTE[i % len(_PALETTE)]
    return c if drone else (c // 2).astype(np.uint8)


def _mark(img: np.ndarray, rc: tuple[int, int], color: np.ndarray, *, filled: bool, half: int = 3) -> None:
    """A square of edge ``2 half + 1`` px centred on ``rc`` (clipped to the image), filled or its outline."""
    h, w = img.shape[:2]
    r, c = rc
    r0, r1, c0, c1 = max(r - half, 0), min(r + half + 1, h), max(c - half, 0), min(c + half + 1, w)
    if r0 >= r1 or c0 >= c1:
        return
    if filled:
        img[r0:r1, c0:c1] = color
        return
    for rr in (r - half, r + half):
        if 0 <= rr < h:
            img[rr, c0:c1] = color
    for cc in (c - half, c + half):
        if 0 <= cc < w:
            img[r0:r1, cc] = color


def _check_counts(n_drones: Any, n_cars: Any) -> None:
    for name, n in (("n_drones", n_drones), ("n_cars", n_cars)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= 16:
            raise ValueError(f"{name} must be an integer in [0, 16], got {n!r}")
    if n_drones + n_cars < 1:
        raise ValueError("the environment needs at least one agent (n_drones + n_cars >= 1)")


def _apply_options(options: dict | None, agents: list[str], starts: np.ndarray, goals: np.ndarray) -> None:
    """``options["starts"]`` ``{agent: [x, y, z, yaw_rad]}`` and ``options["goals"]`` ``{agent: [x, y, z]}``
    (ENU [m]) over the sampled ones; other keys are ignored."""
    if not options:
        return
    for key, table, size in (("starts", starts, 4), ("goals", goals, 3)):
        given = options.get(key) or {}
        if not isinstance(given, dict):
            raise ValueError(f"options[{key!r}] must be a dict agent -> {size} numbers, got {given!r}")
        for agent, value in given.items():
            if agent not in agents:
                raise ValueError(f"options[{key!r}]: no agent {agent!r} (agents: {agents})")
            v = np.asarray(value, dtype=float)
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise ValueError(f"options[{key!r}][{agent!r}] must be {size} finite numbers "
                                 f"({'x, y, z, yaw_rad' if size == 4 else 'x, y, z'}), got {value!r}")
            table[agents.index(agent)] = v


__all__ = ["CAR_MAX_SPEED_M_S", "CAR_MAX_YAW_RATE_RAD_S", "CAR_OBS_LABELS", "CONTROL_HZ", "CityParallelEnv",
           "DRONE_OBS_LABELS", "city_world_text", "nearest_others", "sample_street_point",
           "street_segments"]
