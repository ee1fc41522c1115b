"""Stable-Baselines3 on the batched environment: :class:`SB3VecEnv` makes a :class:`~.envs.DroneVectorEnv`
an SB3 ``VecEnv`` (needs ``stable-baselines3``; ``pip install 'unetyemu_ecs[rl]'``)::

    from stable_baselines3 import PPO
    from unetyemu_ecs.rl.sb3 import make_vec_env

    venv = make_vec_env("hover", num_envs=16)          # SB3VecEnv in a VecMonitor (episode returns logged)
    model = PPO("MlpPolicy", venv).learn(200_000)

SB3's own vector environments (``DummyVecEnv``, ``SubprocVecEnv``) step one Gymnasium environment per
copy; this one steps all the copies as one batch in one physics world, which is several times faster.

Conventions (SB3's, translated from Gymnasium's ``SAME_STEP`` autoreset): a copy whose episode ended
is ``done`` and already reset; its info holds ``terminal_observation`` (the episode's last
observation, Gymnasium's ``infos["final_obs"][i]``) and ``TimeLimit.truncated`` (True when the
episode was cut at the task's duration rather than terminated), besides the task's per-copy figures
(``distance_m``, ``is_success``, ``crashed``, ...).

The copies share one environment: ``seed(s)`` seeds the next ``reset()`` of all of them (the first
seed is used), ``get_attr`` gives the shared environment's attribute once per index, and
``set_attr``/``env_method`` act on the shared environment once, for every copy.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
from stable_baselines3.common.vec_env import VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from .envs import DroneVectorEnv, copy_info


class SB3VecEnv(VecEnv):
    """A :class:`~.envs.DroneVectorEnv` as a Stable-Baselines3 ``VecEnv``.

    Parameters
    ----------
    env : a ``DroneVectorEnv``, or a task name (then ``num_envs`` and ``env_kwargs`` build one)
    num_envs : copies, when ``env`` is a task name
    env_kwargs : further ``DroneVectorEnv`` arguments (``action_level``, ``episode_s``, ...)
    """

    def __init__(self, env: DroneVectorEnv | str = "hover", num_envs: int = 16, **env_kwargs: Any) -> None:
        if isinstance(env, str):
            env = DroneVectorEnv(env, num_envs, **env_kwargs)
        elif env_kwargs:
            raise ValueError("env_kwargs are for building an environment from a task name, not for one given")
        if not isinstance(env, DroneVectorEnv):
            raise TypeError(f"env must be a DroneVectorEnv or a task name, got {env!r}")
        self.env = env
        self._actions: np.ndarray | None = None
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)

    # -- episodes ----------------------------------------------------------------------------------
    def reset(self) -> Any:
        seed = self._seeds[0]
        obs, _info = self.env.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._actions = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions, self._actions = self._actions, None
        obs, reward, terminated, truncated, info = self.env.step(actions)
        dones = np.logical_or(terminated, truncated)
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            item = copy_info(info, i)
            if dones[i]:
                item["terminal_observation"] = info["final_obs"][i]
                item["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            infos.append(item)
        return obs, np.asarray(reward, dtype=np.float32), dones, infos

    def close(self) -> None:
        self.env.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.env.render()
        return [None] * self.num_envs if frames is None else list(frames)

    # -- the shared environment ----------------------------------------------------------------------
    def _count(self, indices: VecEnvIndices) -> int:
        return len(list(self._get_indices(indices)))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.env, attr_name)
        return [value] * self._count(indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.env, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result] * self._count(indices)

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self._count(indices)   # the copies are no gymnasium.Env: nothing wraps them


def make_vec_env(task: str = "hover", num_envs: int = 16, **env_kwargs: Any) -> VecMonitor:
    """``num_envs`` copies of ``task`` as an SB3 ``VecEnv`` in a ``VecMonitor`` (which logs each episode's
    return and length into the infos, ``info["episode"]``, and so into SB3's ``rollout/ep_rew_mean``)."""
    return VecMonitor(SB3VecEnv(task, num_envs, **env_kwargs))


def evaluate(policy: Callable[[Any], np.ndarray], task: str = "hover", episodes: int = 16, seed: int = 0,
             **env_kwargs: Any) -> dict[str, np.ndarray]:
    """Run one episode on each of ``episodes`` copies (reset with ``seed``, so the same starts every call)
    and give each one's ``return``, ``length`` and ``success`` ((episodes,) arrays).

    policy : (episodes, obs...) observations -> (episodes, actions) actions; e.g.
             ``lambda obs: model.predict(obs, deterministic=True)[0]``
    """
    env = DroneVectorEnv(task, episodes, **env_kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        returns = np.zeros(episodes)
        lengths = np.zeros(episodes, dtype=np.int64)
        success = np.zeros(episodes, dtype=bool)
        running = np.ones(episodes, dtype=bool)
        while running.any():
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            returns += np.where(running, reward, 0.0)
            lengths += running
            ended = running & (terminated | truncated)
            success |= ended & np.asarray(info.get("is_success", np.zeros(episodes, dtype=bool)), dtype=bool)
            running &= ~ended
        return {"return": returns, "length": lengths, "success": success}
    finally:
        env.close()


def random_policy(action_space: Any, n: int, seed: int = 0) -> Callable[[Any], np.ndarray]:
    """Uniformly random actions for ``n`` copies from ``action_space`` (one copy's), seeded."""
    rng = np.random.default_rng(seed)
    low, high = action_space.low, action_space.high
    return lambda _obs: rng.uniform(low, high, (n, *action_space.shape)).astype(np.float32)


__all__ = ["SB3VecEnv", "evaluate", "make_vec_env", "random_policy"]
