"""Reinforcement learning on the simulator's flight stack: Gymnasium and PettingZoo environments.

Importing this package registers the Gymnasium ids (``pip install 'unetyemu_ecs[rl]'`` for the
training example; the environments need only ``gymnasium`` and, for the multi-agent one, ``pettingzoo``)::

    import gymnasium as gym
    import unetyemu_ecs.rl  # noqa: F401  (registers unetyemu/Hover-v0, Waypoints-v0, Delivery-v0)

    env = gym.make("unetyemu/Hover-v0")
    envs = gym.make_vec("unetyemu/Hover-v0", num_envs=16, vectorization_mode="vector_entry_point")

(``gym.make("unetyemu_ecs.rl:unetyemu/Hover-v0")`` imports it for you.)
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

ENV_IDS = ("unetyemu/Hover-v0", "unetyemu/Waypoints-v0", "unetyemu/Delivery-v0")

for _id, _task in zip(ENV_IDS, ("Hover", "Waypoints", "Delivery")):
    if _id not in registry:
        register(id=_id, entry_point=f"unetyemu_ecs.rl.envs:{_task}Env",
                 vector_entry_point=f"unetyemu_ecs.rl.envs:{_task}VectorEnv")

__all__ = ["ENV_IDS"]
