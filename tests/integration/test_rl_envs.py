"""The Gymnasium environments: the ecosystem's own checker, physics they must respect, seeding, batching."""

import math
import warnings

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import unetyemu_ecs.rl  # noqa: E402  (registers the ids)
from gymnasium.utils.env_checker import check_env  # noqa: E402
from unetyemu_ecs.components.body import RigidBody  # noqa: E402
from unetyemu_ecs.rl.envs import DroneEnv, DroneVectorEnv  # noqa: E402
from unetyemu_ecs.units import GRAVITY_M_S2  # noqa: E402

ALL_PARTS = ("state", "imu", "gps", "battery", "lidar", "depth")


@pytest.mark.parametrize("env_id", unetyemu_ecs.rl.ENV_IDS)
def test_every_registered_environment_passes_gymnasiums_checker(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # the checker's warnings are failures too
            check_env(env.unwrapped, skip_render_check=False)
        env.reset(seed=0)
        frame = env.render()
        assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8 and frame.std() > 0
    finally:
        env.close()


def test_an_environment_observing_every_sensor_passes_the_checker():
    env = gym.make("unetyemu/Delivery-v0", observations=ALL_PARTS)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
    finally:
        env.close()


def test_hover_thrust_on_every_motor_holds_the_drone_still():
    """The zero action at the motors level is each motor's share of the weight: nothing moves."""
    env = DroneEnv("hover")
    try:
        env.reset(seed=0)
        env.batch.place([0], [[0.0, 0.0, 2.0]], [0.0])
        for _ in range(60):                                       # 2 s
            _obs, _r, terminated, truncated, info = env.step(np.zeros(4))
        pos = env.batch.sim.position_enu_m("drone_0")
        assert np.allclose(pos, [0.0, 0.0, 2.0], atol=0.01)
        assert info["distance_m"] < 0.01 and not terminated
        thrust = env.batch.sim.fleet.motor_thrust_n[env.batch.rows[0]]
        mass = env.batch.sim.component("drone_0", RigidBody).mass_kg
        assert thrust.sum() == pytest.approx(mass * GRAVITY_M_S2, rel=1e-9)
    finally:
        env.close()


def test_less_thrust_than_hover_drops_the_drone_into_the_ground_and_ends_the_episode_as_a_crash():
    env = DroneEnv("hover")
    try:
        env.reset(seed=1)
        for _ in range(300):
            _obs, reward, terminated, truncated, info = env.step(-np.ones(4))
            if terminated:
                break
        assert terminated and info["crashed"] and reward == -10.0
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(4))
    finally:
        env.close()


@pytest.mark.parametrize("level", ["rates", "attitude"])
def test_a_positive_roll_action_puts_the_right_side_down_and_the_drone_moves_right(level):
    env = DroneEnv("hover", action_level=level)
    try:
        env.reset(seed=2)
        env.batch.place([0], [[0.0, 0.0, 2.0]], [0.0])          # facing east: right is south
        action = np.array([0.0, 0.3, 0.0, 0.0])
        for _ in range(6 if level == "rates" else 15):
            env.step(action)
        from unetyemu_ecs.frames import euler_rpy_from_quat_xyzw

        roll, pitch, _ = euler_rpy_from_quat_xyzw(env.batch.sim.attitude_enu_flu_xyzw("drone_0"))
        assert roll > 0.05 and abs(pitch) < 0.5 * roll
        assert env.batch.sim.velocity_enu_m_s("drone_0")[1] < 0.0      # drifting south (right)
    finally:
        env.close()


def test_a_full_east_velocity_action_flies_east_at_the_cruise_speed():
    env = DroneEnv("waypoints", max_speed_m_s=4.0)
    try:
        env.reset(seed=3)
        for _ in range(120):                                        # 4 s
            env.step(np.array([1.0, 0.0, 0.0, 0.0]))
        vel = env.batch.sim.velocity_enu_m_s("drone_0")
        assert vel[0] == pytest.approx(4.0, abs=0.3)
        assert abs(vel[1]) < 0.3 and abs(vel[2]) < 0.3
    finally:
        env.close()


def test_sensor_observations_measure_the_world():
    """IMU at hover reads +g up; GPS is the position; the LiDAR's sector ahead meets the building's wall
    at its known distance and the one behind the ground, where the lowest channel (15 deg down) meets
    it, at h / sin 15 deg; the depth camera sees the wall at its known distance."""
    env = DroneEnv("delivery", observations=ALL_PARTS)
    try:
        env.reset(seed=4)
        env.batch.place([0], [[5.0, 0.0, 4.0]], [0.0])              # facing east, the wall at x = 12 m
        for _ in range(3):
            obs, *_ = env.step(np.zeros(5))
        pos = env.batch.sim.position_enu_m("drone_0")
        assert obs["imu"][5] == pytest.approx(GRAVITY_M_S2, abs=0.05)
        assert np.allclose(obs["imu"][:3], 0.0, atol=0.01)
        assert np.allclose(obs["gps"], pos, atol=1e-3)
        assert obs["battery"][0] <= 1.0 and obs["battery"][0] > 0.99
        ground_m = pos[2] / math.sin(math.radians(15.0))
        assert obs["lidar"][0] * 20.0 == pytest.approx(12.0 - pos[0], abs=0.05)
        assert obs["lidar"][18] * 20.0 == pytest.approx(ground_m, rel=0.02)
        centre = obs["depth"][11:13, 15:17]
        assert np.allclose(centre, 12.0 - pos[0], atol=0.05)
    finally:
        env.close()


def test_the_same_seed_and_actions_give_the_same_episode_and_reset_does_not_rebuild_the_world():
    env = DroneEnv("waypoints", observations=("state", "imu", "lidar"))
    try:
        rng = np.random.default_rng(7)
        actions = rng.uniform(-1, 1, (40, 4))
        client, bodies = env.batch.sim.physics.id, list(env.batch.sim.static_body_ids)

        def episode():
            first, _ = env.reset(seed=11)
            seen = [first]
            for a in actions:
                obs, *_ = env.step(a)
                seen.append(obs)
            return seen

        one, two = episode(), episode()
        for a, b in zip(one, two):
            for part in a:
                assert np.array_equal(a[part], b[part])
        other, _ = env.reset(seed=12)
        assert not np.array_equal(other["state"], one[0]["state"])
        assert env.batch.sim.physics.id == client and list(env.batch.sim.static_body_ids) == bodies
    finally:
        env.close()


def test_copies_in_one_batch_end_their_episodes_independently():
    envs = DroneVectorEnv("hover", 3)
    try:
        obs, _ = envs.reset(seed=5)
        assert obs.shape == (3, len(envs.single_observation_space.low))
        action = np.zeros((3, 4))
        action[1] = -1.0                                        # copy 1 falls
        for _ in range(200):
            obs, reward, terminated, truncated, infos = envs.step(action)
            if terminated[1]:
                break
        assert terminated.tolist() == [False, True, False]
        assert infos["_final_obs"].tolist() == [False, True, False]
        assert infos["final_info"][1]["crashed"]
        assert reward[1] == -10.0 and reward[0] > 0 and reward[2] > 0
        # copy 1 starts again at once: its new first observation is a drone in the air, near its goal
        assert np.linalg.norm(obs[1, :3]) < 2.0 and obs[1, 3:6].max() < 1.0
        assert np.linalg.norm(infos["final_obs"][1][:3]) > 1.0
    finally:
        envs.close()


def test_the_batched_and_the_subprocess_vector_envs_come_from_gymnasium_make_vec():
    batched = gym.make_vec("unetyemu/Hover-v0", num_envs=16, vectorization_mode="vector_entry_point")
    procs = gym.make_vec("unetyemu/Hover-v0", num_envs=2, vectorization_mode="async")
    try:
        assert isinstance(batched.unwrapped, DroneVectorEnv)
        for envs in (batched, procs):
            obs, _ = envs.reset(seed=0)
            obs, reward, terminated, truncated, _ = envs.step(np.zeros((envs.num_envs, 4)))
            assert obs.shape == (envs.num_envs, 17) and reward.shape == (envs.num_envs,)
            assert (reward > 0).all()
    finally:
        batched.close()
        procs.close()


def test_delivery_pickup_joins_the_package_and_a_release_off_the_pad_drops_it():
    env = DroneEnv("delivery")
    try:
        env.reset(seed=6)
        pkg = env.batch.sim.position_enu_m("package_0")
        env.batch.place([0], [pkg + np.array([0.0, 0.0, 0.15 + 0.25])], [0.0])
        power_before = float(env.batch.sim.fleet.power_w[env.batch.rows[0]])
        _obs, reward, terminated, _tr, info = env.step(np.array([0.0, 0.0, 0.0, 0.0, 1.0]))
        assert info["carrying"] and reward > 9.0 and not terminated
        for _ in range(60):                                       # lift it: more power for the same hover
            _obs, reward, terminated, _tr, info = env.step(np.array([0.0, 0.0, 0.3, 0.0, 0.0]))
        assert env.batch.sim.position_enu_m("package_0")[2] > pkg[2] + 1.0
        assert float(env.batch.sim.fleet.power_w[env.batch.rows[0]]) > 1.1 * power_before
        _obs, reward, terminated, _tr, info = env.step(np.array([0.0, 0.0, 0.0, 0.0, -1.0]))
        assert terminated and info["package_dropped"] and reward < -9.0
    finally:
        env.close()


@pytest.mark.parametrize("kwargs, match", [
    ({"task": "hoover"}, "task must be one of"),
    ({"action_level": "thrust"}, "action_level must be one of"),
    ({"observations": ("imu",)}, "observations must name 'state'"),
    ({"observations": ("state", "sonar")}, "'sonar' unknown"),
    ({"control_hz": 70.0}, "must divide the physics rate"),
    ({"control_hz": float("nan")}, "control_hz must be a number"),
    ({"episode_s": -1.0}, "episode_s must be a number"),
    ({"render_mode": "human"}, "render_mode must be None or 'rgb_array'"),
])
def test_bad_settings_are_refused_with_a_message_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DroneEnv(**kwargs)


def test_more_copies_than_the_world_holds_are_refused_before_anything_is_built():
    with pytest.raises(ValueError, match=r"waypoints: at most 398 copies fit in the world"):
        DroneVectorEnv("waypoints", 399)


def test_an_action_of_the_wrong_shape_names_what_an_action_is():
    env = DroneEnv("delivery")
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"5 numbers in \[-1, 1\] \(v_east, v_north, v_up, yaw_rate, gripper\)"):
            env.step(np.zeros(4))
        obs, *_ = env.step(np.full(5, np.nan))             # NaN counts as 0: the drone holds its position
        assert np.isfinite(obs).all()
    finally:
        env.close()
