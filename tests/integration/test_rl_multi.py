"""The multi-agent city (PettingZoo ParallelEnv): drones and cars sharing one physics world, checked
against the PettingZoo API and against what the physics does (collisions, goals, determinism)."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import parallel_api_test, parallel_seed_test  # noqa: E402

from unetyemu_ecs.rl.multi import (CAR_OBS_LABELS, DRONE_OBS_LABELS, GOAL_REWARD, IMPACT_PENALTY,  # noqa: E402
                                   TIME_PENALTY, CityParallelEnv, street_segments)

ALT_M = 20.0      # flight height in these tests: above the trees, below every roof pad and the ceiling


@pytest.fixture(scope="module")
def env():
    e = CityParallelEnv(n_drones=3, n_cars=2, render_mode="rgb_array")
    yield e
    e.close()


def north_south_streets(env: CityParallelEnv) -> list[float]:
    """x [m] of the centre lines of the streets running north-south, west to east."""
    s = street_segments(env.sim.layout)
    return sorted(float(x) for x, ux in zip(s[:, 0], s[:, 2]) if abs(ux) < 1e-9)


def scenario(env: CityParallelEnv, starts: dict, goals: dict) -> dict:
    """Reset options: the named agents where given, every other agent parked out of the way (drones
    hovering over the west street, cars in the east street's lanes), each with a distant goal."""
    west, _, east = north_south_streets(env)
    out_s, out_g = {}, {}
    for k, d in enumerate(env.drones):
        out_s[d] = starts.get(d, [west, -40.0 + 20.0 * k, ALT_M, 0.0])
        out_g[d] = goals.get(d, [west, 60.0, ALT_M])
    for k, c in enumerate(env.cars):
        out_s[c] = starts.get(c, [east + 3.0, -40.0 + 20.0 * k, 0.0, math.pi / 2])
        out_g[c] = goals.get(c, [east + 3.0, 60.0, 0.0])
    return {"starts": out_s, "goals": out_g}


def hold(env: CityParallelEnv) -> dict:
    return {a: np.zeros(env.action_space(a).shape, dtype=np.float32) for a in env.agents}


def seeded_actions(env: CityParallelEnv, rng: np.random.Generator) -> dict:
    return {a: rng.uniform(-1.0, 1.0, env.action_space(a).shape).astype(np.float32) for a in env.agents}


# -- the PettingZoo contract --------------------------------------------------------------------------
def test_the_environment_passes_pettingzoos_parallel_api_test(env):
    parallel_api_test(env, num_cycles=40)


def test_two_environments_seeded_alike_step_alike_under_pettingzoos_seed_test():
    parallel_seed_test(lambda: CityParallelEnv(n_drones=2, n_cars=1), num_cycles=20)


def test_spaces_are_float32_boxes_cached_per_agent_and_the_agents_are_named_by_kind(env):
    assert env.possible_agents == ["drone_0", "drone_1", "drone_2", "car_0", "car_1"]
    assert env.metadata["name"] == "unetyemu_city_v0" and env.metadata["is_parallelizable"]
    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(agent)
        assert env.action_space(agent) is env.action_space(agent)
        assert env.observation_space(agent).dtype == np.float32 == env.action_space(agent).dtype
    assert env.observation_space("drone_0").shape == (len(DRONE_OBS_LABELS),) == (19,)
    assert env.observation_space("car_0").shape == (len(CAR_OBS_LABELS),) == (15,)
    assert env.action_space("drone_0").shape == (4,) and env.action_space("car_0").shape == (2,)


# -- what an agent sees -------------------------------------------------------------------------------
def test_the_observation_holds_goal_offset_velocity_attitude_and_the_nearest_vehicle_as_documented(env):
    _, middle, _ = north_south_streets(env)
    opts = scenario(env, {"drone_0": [middle, -30.0, ALT_M, math.pi / 2], "drone_1": [middle, -20.0, 25.0, 0.0],
                          "car_0": [middle + 3.0, 30.0, 0.0, math.pi / 2]},
                    {"drone_0": [middle + 5.0, 0.0, 15.0], "car_0": [middle + 3.0, 60.0, 0.0]})
    obs, infos = env.reset(seed=1, options=opts)
    assert env.agents == env.possible_agents
    d = obs["drone_0"]
    assert d.dtype == np.float32 and env.observation_space("drone_0").contains(d)
    np.testing.assert_allclose(d[0:3], [5.0, 30.0, -5.0], atol=1e-4)         # goal - position, ENU [m]
    np.testing.assert_allclose(d[3:6], 0.0, atol=1e-6)                       # at rest [m/s]
    s = math.sin(math.pi / 4)
    np.testing.assert_allclose(d[6:10], [0.0, 0.0, s, s], atol=1e-6)         # facing north: yaw 90 deg, xyzw
    np.testing.assert_allclose(d[10:13], 0.0, atol=1e-6)                     # body rates [rad/s]
    np.testing.assert_allclose(d[13:16], [0.0, 10.0, 5.0], atol=1e-4)        # drone_1, 10 m north, 5 m up
    assert infos["drone_0"]["distance_m"] == pytest.approx(math.sqrt(25 + 900 + 25))
    c = obs["car_0"]
    np.testing.assert_allclose(c[0:3], [0.0, 30.0, 0.0], atol=1e-3)          # a car's goal is at its own height
    np.testing.assert_allclose(c[6:8], [0.0, 1.0], atol=1e-3)                # heading north: cos, sin
    assert infos["car_0"]["distance_m"] == pytest.approx(30.0, abs=1e-3)


def test_sampled_starts_and_goals_lie_over_the_streets_and_change_with_the_seed(env):
    env.reset(seed=11)
    goals_11 = env.goals
    env.reset(seed=12)
    assert not np.allclose(goals_11["drone_0"], env.goals["drone_0"])
    env.reset(seed=11)
    for agent, goal in env.goals.items():
        np.testing.assert_array_equal(goal, goals_11[agent])
        x, y, z = goal
        # over a street: no building, sidewalk or tree footprint under it
        assert env.sim.layout.surface_height_m(x, y) < 0.01, agent
        if agent.startswith("drone"):
            assert 10.0 <= z <= 30.0
        assert np.linalg.norm(goal[:2] - env.sim.position_enu_m(agent)[:2]) >= 20.0


# -- what the physics does ----------------------------------------------------------------------------
def test_two_drones_flown_into_each_other_both_terminate_with_the_collision_penalty(env):
    _, middle, _ = north_south_streets(env)
    opts = scenario(env, {"drone_0": [middle, -8.0, ALT_M, 0.0], "drone_1": [middle, 8.0, ALT_M, 0.0]},
                    {"drone_0": [middle + 60.0, -70.0, ALT_M], "drone_1": [middle + 60.0, 70.0, ALT_M]})
    env.reset(seed=2, options=opts)
    events_before = len(env.sim.events)
    for _ in range(150):
        actions = hold(env)
        actions["drone_0"] = np.array([0.0, 1.0, 0.0, 0.0], dtype=np.float32)     # full speed north
        actions["drone_1"] = np.array([0.0, -1.0, 0.0, 0.0], dtype=np.float32)    # full speed south
        _, rewards, terminations, _, infos = env.step(actions)
        if terminations["drone_0"] or terminations["drone_1"]:
            break
    else:
        pytest.fail("the drones never collided")
    gap = np.linalg.norm(env.sim.position_enu_m("drone_0") - env.sim.position_enu_m("drone_1"))
    # both at once, each with the penalty, each naming the other
    assert terminations["drone_0"] and terminations["drone_1"]
    for me, other in (("drone_0", "drone_1"), ("drone_1", "drone_0")):
        assert rewards[me] < -IMPACT_PENALTY + 1.0
        assert infos[me]["reason"] == "impact" and infos[me]["hit"] == other
    assert gap < 1.5                                              # they touched: bodies a few decimetres wide
    # the simulator's own impact monitor saw it: a real contact between the two bodies, fast enough
    impacts = [(v, text) for _, v, text in env.sim.events[events_before:] if text.startswith("impact with")]
    assert any({v, text.split()[2]} == {"drone_0", "drone_1"} for v, text in impacts), impacts
    assert env.sim.fleet.impacts[env.sim.row("drone_0")] >= 1 and env.sim.fleet.impacts[env.sim.row("drone_1")] >= 1
    # the others fly on; the two are gone from the agents and get nothing more
    assert env.agents == ["drone_2", "car_0", "car_1"]
    obs, rewards, *_ = env.step(hold(env))
    assert set(obs) == set(rewards) == {"drone_2", "car_0", "car_1"}


def test_a_drone_flown_at_full_speed_toward_its_goal_earns_progress_and_reaches_it(env):
    _, middle, _ = north_south_streets(env)
    start, goal = np.array([middle, -35.0, ALT_M]), np.array([middle, -15.0, 25.0])
    obs, _ = env.reset(seed=3, options=scenario(env, {"drone_0": [*start, 0.0]}, {"drone_0": goal}))
    rewards = []
    for _ in range(300):
        rel = obs["drone_0"][:3]
        actions = hold(env)
        actions["drone_0"] = np.array([*rel[:2] / np.linalg.norm(rel[:2]), np.clip(rel[2] / 2.0, -1, 1), 0.0],
                                      dtype=np.float32)
        obs, reward, terminations, _, infos = env.step(actions)
        rewards.append(reward["drone_0"])
        if terminations["drone_0"]:
            break
    assert infos["drone_0"]["reason"] == "goal"
    assert np.linalg.norm(env.sim.position_enu_m("drone_0") - goal) <= 2.0
    assert rewards[-1] > GOAL_REWARD
    assert all(r > 0.0 for r in rewards[6:-1])                    # once moving, every step closes distance
    # the rewards add up to the metres closed, less the time penalty of every step, plus the bonus
    closed_m = np.linalg.norm(goal - start) - infos["drone_0"]["distance_m"]
    assert sum(rewards) == pytest.approx(closed_m - TIME_PENALTY * len(rewards) + GOAL_REWARD, abs=1e-9)
    assert "drone_0" not in env.agents


def test_a_car_given_a_full_forward_action_drives_along_its_lane_and_stops_when_its_episode_ends(env):
    _, middle, _ = north_south_streets(env)
    opts = scenario(env, {"car_0": [middle + 3.0, -40.0, 0.0, math.pi / 2]}, {"car_0": [middle + 3.0, -28.0, 0.0]})
    env.reset(seed=4, options=opts)
    for _ in range(150):
        actions = hold(env)
        actions["car_0"] = np.array([1.0, 0.0], dtype=np.float32)
        _, _, terminations, _, infos = env.step(actions)
        if terminations["car_0"]:
            break
    assert infos["car_0"]["reason"] == "goal"
    pos = env.sim.position_enu_m("car_0")
    assert abs(pos[0] - (middle + 3.0)) < 0.5 and pos[1] > -32.0  # straight up its lane, within 4 m
    assert env.sim.velocity_enu_m_s("car_0")[1] > 3.0
    for _ in range(75):                                           # 2.5 s: braked to a stop
        env.step(hold(env))
    assert np.linalg.norm(env.sim.velocity_enu_m_s("car_0")) < 0.2


def test_a_car_that_ended_an_episode_driving_starts_the_next_at_rest_without_an_impact(env):
    env.reset(seed=10)
    for _ in range(45):
        env.step({c: np.array([1.0, 0.0], dtype=np.float32) for c in env.cars if c in env.agents})
    assert max(np.linalg.norm(env.sim.velocity_enu_m_s(c)) for c in env.cars) > 3.0
    env.reset(seed=11)
    for _ in range(5):
        _, _, terminations, _, infos = env.step(hold(env))
        for car in env.cars:
            assert not terminations[car], infos[car]
    assert all(env.sim.fleet.impacts[env.sim.row(c)] == 0 for c in env.cars)


def test_the_same_seed_and_actions_give_the_same_observations_in_a_reused_and_a_fresh_environment(env):
    def episode(e: CityParallelEnv, seed: int, n: int = 20) -> list[dict]:
        obs, _ = e.reset(seed=seed)
        rng = np.random.default_rng(seed)
        trace = [obs]
        for _ in range(n):
            if not e.agents:
                break
            trace.append(e.step(seeded_actions(e, rng))[0])
        return trace

    first = episode(env, 5)
    at_once = episode(env, 5)             # the vehicles put back where they stood a moment ago
    episode(env, 6)                       # another episode in between (cars driving, drones flying)
    again = episode(env, 5)
    fresh_env = CityParallelEnv(n_drones=3, n_cars=2)
    try:
        fresh = episode(fresh_env, 5)
    finally:
        fresh_env.close()
    for trace in (at_once, again, fresh):
        assert len(trace) == len(first)
        for a, b in zip(first, trace):
            assert a.keys() == b.keys()
            for agent in a:
                np.testing.assert_array_equal(a[agent], b[agent])


# -- misuse -------------------------------------------------------------------------------------------
def test_an_action_of_the_wrong_shape_is_refused_naming_the_agent_and_the_shape_expected(env):
    env.reset(seed=7)
    bad = hold(env)
    bad["drone_1"] = np.zeros(3)
    with pytest.raises(ValueError, match=r"drone_1 must have shape \(4,\), got shape \(3,\)"):
        env.step(bad)
    bad = hold(env)
    bad["car_1"] = np.zeros(4)
    with pytest.raises(ValueError, match=r"car_1 must have shape \(2,\)"):
        env.step(bad)
    with pytest.raises(ValueError, match="unknown agents"):
        env.step({"drone_9": np.zeros(4)})


def test_a_nan_in_an_action_counts_as_zero(env):
    env.reset(seed=8)
    zero = env.step(hold(env))[0]
    env.reset(seed=8)
    actions = hold(env)
    actions["drone_0"] = np.full(4, np.nan, dtype=np.float32)
    actions["car_0"] = np.array([np.nan, 0.0], dtype=np.float32)
    nan = env.step(actions)[0]
    for agent in zero:
        np.testing.assert_array_equal(zero[agent], nan[agent])


def test_every_agent_still_going_is_truncated_at_the_time_limit():
    e = CityParallelEnv(n_drones=1, n_cars=1, max_episode_s=0.2)
    try:
        with pytest.raises(RuntimeError, match="reset"):
            e.step({})
        e.reset(seed=0)
        for _ in range(6):                                      # 0.2 s at 30 Hz
            assert e.agents == ["drone_0", "car_0"]
            _, _, terminations, truncations, infos = e.step({})
        assert truncations == {"drone_0": True, "car_0": True}
        assert terminations == {"drone_0": False, "car_0": False}
        assert infos["drone_0"]["reason"] == "time_limit" and e.agents == []
        assert e.step({}) == ({}, {}, {}, {}, {})
    finally:
        e.close()
    e.close()                                                   # twice is fine


def test_render_draws_the_city_from_above_with_every_agent_marked(env):
    env.reset(seed=9)
    frame = env.render()
    assert frame.shape == (256, 256, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10     # streets, blocks, roofs, trees, markers
    env.step({"drone_0": np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32)})
    for _ in range(30):
        env.step({"drone_0": np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32)})
    assert not np.array_equal(frame, env.render())              # the drone's marker moved
