"""Gymnasium environments on the simulator's own flight stack: one drone (``DroneEnv``), or many
independent copies of its task stepped as one batch (``DroneVectorEnv``, Gymnasium's vector API).

Both run a :class:`~.flight_batch.FlightBatch`: the copies share one physics world (each on a
patch of its own) and every physics step moves all of them with one pass of each system, so 16
copies cost far less than 16 environments. ``reset()`` restores the state saved after the world was
built (it never rebuilds it). Seeded: ``reset(seed=s)`` followed by the same actions gives the same
observations, bit for bit.

Observations: ``observations=("state",)`` (default) gives a float32 ``Box`` of the task's state
(see :mod:`.tasks` for its elements, :attr:`DroneEnv.state_labels` for their names); adding any of
``imu``, ``gps``, ``battery``, ``lidar``, ``depth`` (:mod:`.observations`) gives a ``Dict`` of
float32 Boxes keyed by part.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..config.limits import MAX_XY_M
from .actions import ACTION_LABELS, ACTION_LEVELS
from .flight_batch import FlightBatch
from .observations import (SENSOR_PARTS, SensorSetup, bounds_by_unit, check_parts, part_bounds, read_part,
                           sensor_components)
from .tasks import TASKS, DroneTask

RENDER_SIZE = (240, 320)          # (height, width) of an rgb_array frame [px]
MAX_COPIES = 1024
MAX_STATE_DISTANCE_M = 500.0      # bounds of a distance in a task's state [m]


def _check_number(name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


class _Copies:
    """The task, the batch and the observation of N copies: what both environment classes share."""

    def __init__(self, task: str, n: int, action_level: str | None, observations: Any, control_hz: float,
                 physics_hz: float, episode_s: float | None, sensors: SensorSetup | None, max_speed_m_s: float | None,
                 world_seed: int) -> None:
        if task not in TASKS:
            raise ValueError(f"task must be one of {', '.join(TASKS)}, got {task!r}")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_COPIES:
            raise ValueError(f"the number of copies must be an integer in [1, {MAX_COPIES}], got {n!r}")
        most = min(MAX_COPIES, int(2.0 * MAX_XY_M // TASKS[task].spacing_m) - 2)   # the ground under every copy
        if n > most:
            raise ValueError(f"{task}: at most {most} copies fit in the world (each {TASKS[task].spacing_m:g} m "
                             f"apart on a ground of at most {2.0 * MAX_XY_M:g} m), got {n}")
        self.task: DroneTask = TASKS[task](int(n))
        level = self.task.default_level if action_level is None else action_level
        if level not in ACTION_LEVELS:
            raise ValueError(f"action_level must be one of {', '.join(ACTION_LEVELS)}, got {level!r}")
        self.parts = check_parts(observations)
        self.setup = sensors if sensors is not None else SensorSetup()
        if not isinstance(self.setup, SensorSetup):
            raise ValueError(f"sensors must be a SensorSetup, got {sensors!r}")
        physics_hz = _check_number("physics_hz", physics_hz, 50.0, 2000.0)
        control_hz = _check_number("control_hz", control_hz, 1.0, physics_hz)
        self.episode_s = self.task.episode_s if episode_s is None else _check_number("episode_s", episode_s, 0.1, 3600.0)
        if max_speed_m_s is not None:
            _check_number("max_speed_m_s", max_speed_m_s, 0.1, 50.0)
        sensors_yaml = sensor_components(self.parts, self.setup, control_hz)
        self.batch = FlightBatch(self.task.world_yaml(physics_hz, world_seed, sensors_yaml), self.task.drones, level,
                                 control_hz, max_speed_m_s=max_speed_m_s, file=f"<{self.task.name} environment>")
        self.level = level
        self.episode_steps = max(1, int(round(self.episode_s / self.batch.control_dt_s)))
        self.steps = np.zeros(int(n), dtype=np.int64)
        self.full_voltage_v = self.batch.sim.fleet.pack_voltage_v[self.batch.rows].copy()
        n_act = 4 + self.task.extra_actions
        self.action_space = spaces.Box(-1.0, 1.0, (n_act,), dtype=np.float32)
        self.state_low, self.state_high = bounds_by_unit(self.task.state_labels, MAX_STATE_DISTANCE_M)
        state = spaces.Box(self.state_low, self.state_high, dtype=np.float32)
        if self.parts == ("state",):
            self.observation_space: spaces.Space = state
        else:
            boxes: dict[str, spaces.Space] = {"state": state}
            for part in self.parts:
                if part in SENSOR_PARTS:
                    shape, low, high = part_bounds(part, self.setup)
                    boxes[part] = spaces.Box(low, high, shape, dtype=np.float32)
            self.observation_space = spaces.Dict(boxes)

    # -- episodes ----------------------------------------------------------------------------------
    def reset_all(self, rng: np.random.Generator, seed: int | None) -> None:
        self.batch.restore(seed)
        self.task.start(self.batch, np.arange(self.task.n), rng)
        self.steps[:] = 0
        self.batch.measure_sensors()

    def reset_some(self, k: np.ndarray, rng: np.random.Generator) -> None:
        self.task.start(self.batch, k, rng)
        self.steps[k] = 0
        if len(self.parts) > 1:
            self.batch.measure_sensors()

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        n, width = self.task.n, self.action_space.shape[0]
        a = np.asarray(actions, dtype=float)
        if a.size != n * width:
            raise ValueError(f"{self.task.name}: an action is {width} numbers in [-1, 1] "
                             f"({', '.join(self.action_labels)}) per copy ({n}), got shape {a.shape}")
        a = a.reshape(n, width)
        self.batch.act(a[:, :4])
        if self.task.extra_actions:
            self.task.before_step(self.batch, a[:, 4:])
        self.batch.advance()
        self.steps += 1
        out = self.task.outcome(self.batch)
        truncated = (self.steps >= self.episode_steps) & ~out.terminated
        return out.reward, out.terminated, truncated, out.info

    @property
    def action_labels(self) -> tuple[str, ...]:
        return ACTION_LABELS[self.level] + (("gripper",) if self.task.extra_actions else ())

    def observe(self) -> Any:
        """Observations of every copy: (N, state) float32, or a dict of (N, ...) float32 by part."""
        state = np.clip(self.task.state(self.batch), self.state_low, self.state_high).astype(np.float32)
        if self.parts == ("state",):
            return state
        out = {"state": state}
        sim, names = self.batch.sim, self.task.drones
        for part in self.parts:
            if part in SENSOR_PARTS:
                out[part] = np.stack([read_part(sim, names[i], part, self.setup, self.task.origin[i],
                                                float(self.full_voltage_v[i]))
                                      for i in range(self.task.n)]).astype(np.float32)
        return out

    def render(self, i: int) -> np.ndarray:
        """An (H, W, 3) uint8 view of copy ``i`` from behind and above its drone (PyBullet's CPU renderer)."""
        import pybullet as p

        sim = self.batch.sim
        pos = sim.fleet.pos_enu_m[self.batch.rows[i]]
        h, w = RENDER_SIZE
        view = p.computeViewMatrix(cameraEyePosition=(pos + np.array([-6.0, -6.0, 4.0])).tolist(),
                                   cameraTargetPosition=pos.tolist(), cameraUpVector=[0, 0, 1],
                                   physicsClientId=sim.physics.id)
        proj = p.computeProjectionMatrixFOV(fov=60.0, aspect=w / h, nearVal=0.1, farVal=200.0,
                                            physicsClientId=sim.physics.id)
        _w, _h, rgba, _depth, _seg = p.getCameraImage(w, h, view, proj, renderer=p.ER_TINY_RENDERER,
                                                      physicsClientId=sim.physics.id)
        return np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3].copy()

    def close(self) -> None:
        self.batch.close()


def _take(obs: Any, i: int) -> Any:
    return {k: v[i] for k, v in obs.items()} if isinstance(obs, dict) else obs[i]


def copy_info(info: dict[str, Any], i: int) -> dict[str, Any]:
    """Copy ``i``'s figures of a batch's info (name -> (N,) array) as plain Python values, without the
    vector API's own keys (``final_obs``, ``final_info`` and the ``_`` masks)."""
    return {k: (v[i].item() if isinstance(v[i], np.generic) else v[i]) for k, v in info.items()
            if not k.startswith("_") and k not in ("final_obs", "final_info")}


class DroneEnv(gym.Env):
    """One drone and its task (``hover``, ``waypoints``, ``delivery``; see :mod:`.tasks`).

    Parameters
    ----------
    task : which task
    action_level : ``motors``, ``rates``, ``attitude`` or ``velocity`` (:mod:`.actions`); None: the task's
    observations : parts to observe, ``state`` first (:mod:`.observations`)
    control_hz : actions per simulated second (default 30, as gym-pybullet-drones)
    physics_hz : physics steps per simulated second (default 240); a whole multiple of ``control_hz``
    episode_s : episode length before truncation [s, sim]; None: the task's
    sensors : LiDAR and depth-image settings (:class:`~.observations.SensorSetup`)
    max_speed_m_s : horizontal speed of a full velocity action (None: the drone's cruise speed)
    render_mode : None or ``"rgb_array"``
    world_seed : the world's seed (the simulator's own noise; episodes are seeded by ``reset(seed=...)``)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, task: str = "hover", *, action_level: str | None = None, observations: Any = ("state",),
                 control_hz: float = 30.0, physics_hz: float = 240.0, episode_s: float | None = None,
                 sensors: SensorSetup | None = None, max_speed_m_s: float | None = None,
                 render_mode: str | None = None, world_seed: int = 0) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self._copies = _Copies(task, 1, action_level, observations, control_hz, physics_hz, episode_s, sensors,
                               max_speed_m_s, world_seed)
        self.metadata = {**self.metadata, "render_fps": int(round(control_hz))}
        self.action_space = self._copies.action_space
        self.observation_space = self._copies.observation_space
        self._done = True

    @property
    def state_labels(self) -> tuple[str, ...]:
        """The name of each element of the ``state`` observation, with its unit."""
        return self._copies.task.state_labels

    @property
    def action_labels(self) -> tuple[str, ...]:
        return self._copies.action_labels

    @property
    def batch(self) -> FlightBatch:
        """The simulation underneath (``batch.sim`` is the :class:`~unetyemu_ecs.app.Simulation`)."""
        return self._copies.batch

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self._copies.reset_all(self.np_random, seed)
        self._done = False
        return _take(self._copies.observe(), 0), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._done:
            raise RuntimeError("step() after the episode ended: call reset() first")
        reward, terminated, truncated, info = self._copies.step(action)
        self._done = bool(terminated[0] or truncated[0])
        return (_take(self._copies.observe(), 0), float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                copy_info(info, 0))

    def render(self) -> np.ndarray | None:
        return self._copies.render(0) if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self._copies.close()


class DroneVectorEnv(VectorEnv):
    """``num_envs`` independent copies of one task, stepped as one batch in one simulation.

    Episodes end independently; a copy whose episode ended is reset in the same step (Gymnasium's
    ``AutoresetMode.SAME_STEP``): the step returns its new episode's first observation, and its last
    observation and info under ``infos["final_obs"]`` and ``infos["final_info"]`` (masks
    ``infos["_final_obs"]``, ``infos["_final_info"]``). Other parameters as :class:`DroneEnv`.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, task: str = "hover", num_envs: int = 16, *, action_level: str | None = None,
                 observations: Any = ("state",), control_hz: float = 30.0, physics_hz: float = 240.0,
                 episode_s: float | None = None, sensors: SensorSetup | None = None, max_speed_m_s: float | None = None,
                 render_mode: str | None = None, world_seed: int = 0) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self._copies = _Copies(task, num_envs, action_level, observations, control_hz, physics_hz, episode_s,
                               sensors, max_speed_m_s, world_seed)
        self.num_envs = int(num_envs)
        self.single_action_space = self._copies.action_space
        self.single_observation_space = self._copies.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._started = False

    @property
    def batch(self) -> FlightBatch:
        return self._copies.batch

    def reset(self, *, seed: int | list[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if isinstance(seed, list):
            seed = seed[0] if seed else None
        super().reset(seed=seed)
        self._copies.reset_all(self.np_random, seed)
        self._started = True
        return self._copies.observe(), {}

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("step() before reset(): call reset() first")
        reward, terminated, truncated, info = self._copies.step(actions)
        infos: dict[str, Any] = dict(info)
        ended = np.flatnonzero(terminated | truncated)
        if ended.size:
            final = self._copies.observe()
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[ended] = True
            final_obs = np.empty(self.num_envs, dtype=object)
            final_info = np.empty(self.num_envs, dtype=object)
            for i in ended.tolist():
                final_obs[i] = _take(final, i)
                final_info[i] = copy_info(info, i)
            self._copies.reset_some(ended, self.np_random)
            infos.update({"final_obs": final_obs, "_final_obs": mask, "final_info": final_info, "_final_info": mask})
        return self._copies.observe(), reward, terminated, truncated, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        return tuple(self._copies.render(i) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        self._copies.close()


def _task_env(task: str) -> type:
    def __init__(self: Any, **kwargs: Any) -> None:
        DroneEnv.__init__(self, task, **kwargs)

    return type(f"{task.capitalize()}Env", (DroneEnv,), {"__init__": __init__, "__module__": __name__,
                                                          "__doc__": f"``DroneEnv('{task}')``."})


def _task_vector_env(task: str) -> type:
    def __init__(self: Any, num_envs: int = 16, **kwargs: Any) -> None:
        DroneVectorEnv.__init__(self, task, num_envs, **kwargs)

    return type(f"{task.capitalize()}VectorEnv", (DroneVectorEnv,),
                {"__init__": __init__, "__module__": __name__, "__doc__": f"``DroneVectorEnv('{task}', num_envs)``."})


HoverEnv, WaypointsEnv, DeliveryEnv = (_task_env(t) for t in ("hover", "waypoints", "delivery"))
HoverVectorEnv, WaypointsVectorEnv, DeliveryVectorEnv = (_task_vector_env(t) for t in ("hover", "waypoints", "delivery"))

__all__ = ["DeliveryEnv", "copy_info", "DeliveryVectorEnv", "DroneEnv", "DroneVectorEnv", "HoverEnv", "HoverVectorEnv",
           "RENDER_SIZE", "WaypointsEnv", "WaypointsVectorEnv"]
