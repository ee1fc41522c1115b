"""IMU, GPS, battery and odometry sensors checked against physics and against a WGS84 reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geographiclib.geodesic import Geodesic

from unetyemu_ecs import Simulation, load_world_text
from unetyemu_ecs.frames import quat_multiply_xyzw, quat_conjugate_xyzw
from unetyemu_ecs.sensors.messages import deserialize, serialize

G = 9.81
ORIGIN = (40.4168, -3.7038, 650.0)


def world(vehicles: str, ground_m: float = 300.0) -> str:
    return f"""
world: {{name: sensors, physics_hz: 240, seed: 11,
         origin: {{lat_deg: {ORIGIN[0]}, lon_deg: {ORIGIN[1]}, alt_m: {ORIGIN[2]}}}}}
scene: {{generator: none, ground_size_m: {ground_m}}}
vehicles:
{vehicles}
"""


def drone(name: str, sensors: str, pos: str = "[0.0, 0.0, 0.3]", extra: str = "") -> str:
    return (f"  - name: {name}\n    type: quadrotor\n    preset: medium\n    pose: {{position_m: {pos}}}\n"
            f"    components: {{{sensors}{extra}}}\n")


def vec(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def collect(sim: Simulation, vehicle: str, sensor: str, steps: int) -> list:
    """Every message of one sensor over the next ``steps`` steps."""
    out = []
    for _ in range(steps):
        sim.step()
        out += [s.msg for s in sim.services.sensors.this_step if s.vehicle == vehicle and s.sensor == sensor]
    return out


def test_imu_at_rest_reads_plus_g_up_and_no_rotation():
    with Simulation(load_world_text(world(drone("d1", "imu: {}")))) as sim:
        sim.run(duration=2.0)
        msgs = collect(sim, "d1", "imu", 240)
        acc = np.array([vec(m.linear_acceleration) for m in msgs])
        assert len(msgs) == 100                                  # 100 Hz by default
        assert np.allclose(acc.mean(axis=0), [0.0, 0.0, G], atol=2e-3)
        assert np.abs(np.array([vec(m.angular_velocity) for m in msgs])).max() < 1e-3


def test_imu_noise_has_the_configured_spread_around_the_truth_and_is_seeded():
    sensors = "imu: {gyro_noise_std_rad_s: 0.01, accel_noise_std_m_s2: 0.2}"
    runs = []
    for _ in range(2):
        with Simulation(load_world_text(world(drone("d1", sensors)))) as sim:
            sim.run(duration=1.0)
            msgs = collect(sim, "d1", "imu", 240 * 20)
            runs.append(np.array([vec(m.linear_acceleration) for m in msgs]))
    acc = runs[0]
    assert np.array_equal(runs[0], runs[1])                     # same seed, same noise
    assert np.allclose(acc.std(axis=0), 0.2, rtol=0.1)
    assert np.allclose(acc.mean(axis=0), [0, 0, G], atol=4 * 0.2 / np.sqrt(len(acc)))
    assert msgs[-1].linear_acceleration_covariance[0] == pytest.approx(0.04)


def test_imu_in_free_fall_reads_almost_nothing():
    # a drone without drag, motors off, dropped from 60 m
    no_drag = ", aero_drag: {drag_coeff: 0.0, area_flu_m2: [0.0, 0.0, 0.0]}"
    with Simulation(load_world_text(world(drone("d1", "imu: {}", pos="[0.0, 0.0, 60.0]", extra=no_drag)))) as sim:
        msgs = collect(sim, "d1", "imu", 240)
        acc = np.array([vec(m.linear_acceleration) for m in msgs[5:]])
        assert sim.velocity_enu_m_s("d1")[2] == pytest.approx(-G * sim.sim_time_s, rel=0.01)
        assert np.abs(acc).max() < 0.01


def test_imu_reads_the_yaw_rate_the_attitude_shows():
    with Simulation(load_world_text(world(drone("d1", "imu: {}")))) as sim:
        sim.set_target("d1", 0.0, 0.0, 10.0)
        sim.run(duration=8.0)
        sim.teleop("d1", 0.0, 0.0, 0.0, 0.5)                     # turn left at half the yaw-rate limit
        sim.run(duration=3.0)
        q0 = sim.attitude_enu_flu_xyzw("d1").copy()
        msgs = collect(sim, "d1", "imu", 240)
        q1 = sim.attitude_enu_flu_xyzw("d1")
        dq = quat_multiply_xyzw(quat_conjugate_xyzw(q0), q1)     # rotation over 1 s, body frame
        rate_from_attitude = 2.0 * math.atan2(dq[2], dq[3]) / 1.0
        gyro_z = np.array([m.angular_velocity.z for m in msgs])
        assert rate_from_attitude == pytest.approx(math.radians(45.0), rel=0.05)
        assert gyro_z.mean() == pytest.approx(rate_from_attitude, rel=0.01)


def test_imu_mounted_on_its_side_sees_gravity_on_its_own_axis():
    sensors = "imu: {mount_rpy_deg: [90.0, 0.0, 0.0]}"          # rolled 90 deg: sensor y is body up
    with Simulation(load_world_text(world(drone("d1", sensors)))) as sim:
        sim.run(duration=1.0)
        acc = vec(sim.sensor("d1", "imu").linear_acceleration)
        assert np.allclose(acc, [0.0, G, 0.0], atol=2e-3)


def test_gps_1000_m_north_reports_the_wgs84_latitude_within_0_1_m():
    # GIVEN a drone resting on the ground 1000 m north of the world origin
    with Simulation(load_world_text(world(drone("d1", "gps: {}", pos="[0.0, 1000.0, 0.3]"), ground_m=2200.0))) as sim:
        sim.run(duration=1.0)
        fix = sim.sensor("d1", "gps")
        north_m = sim.position_enu_m("d1")[1]
        # THEN latitude/longitude are where a geodesic due north from the origin ends, its length the
        # tangent-plane distance brought down from the origin's altitude h to the ellipsoid: d M / (M + h)
        a, f = Geodesic.WGS84.a, Geodesic.WGS84.f
        e2 = f * (2 - f)
        meridian_m = a * (1 - e2) / (1 - e2 * math.sin(math.radians(ORIGIN[0])) ** 2) ** 1.5
        ref = Geodesic.WGS84.Direct(ORIGIN[0], ORIGIN[1], 0.0, north_m * meridian_m / (meridian_m + ORIGIN[2]))
        m_per_deg_lat = 111_030.0                               # at 40.4 deg (only scales the tolerance)
        assert abs(fix.latitude - ref["lat2"]) * m_per_deg_lat < 0.1
        assert abs(fix.longitude - ORIGIN[1]) * 85_000.0 < 0.1
        # AND altitude: 8 cm above the origin's height, plus the ellipsoid's drop over 1 km (d^2 / 2R ~ 8 cm)
        assert fix.altitude == pytest.approx(ORIGIN[2] + 0.08 + north_m ** 2 / (2 * 6_371_000.0), abs=0.02)
        assert fix.status.status == 0 and fix.position_covariance_type == 2


def test_battery_state_follows_the_energy_model():
    with Simulation(load_world_text(world(drone("d1", "battery: {}")))) as sim:
        sim.set_target("d1", 0.0, 0.0, 10.0)
        sim.run(duration=10.0)
        msg = sim.sensor("d1", "battery")
        row = sim.row("d1")
        f = sim.fleet
        assert msg.percentage == pytest.approx(f.soc_frac[row], abs=1e-3)
        # the pack's terminal voltage and current carry the power drawn (ROS: negative while discharging)
        assert msg.voltage * -msg.current == pytest.approx(f.power_w[row], rel=0.02)
        assert msg.voltage == pytest.approx(f.pack_voltage_v[row], rel=0.01)
        assert 6 * 3.5 < msg.voltage < 6 * 4.2 and len(msg.cell_voltage) == 6
        assert sum(msg.cell_voltage) == pytest.approx(msg.voltage, rel=1e-5)
        assert msg.design_capacity == pytest.approx(500 / 22.2)            # 500 Wh at 6 x 3.7 V
        assert msg.capacity == pytest.approx(msg.design_capacity)          # a new pack: no fade yet
        assert msg.charge == pytest.approx(msg.percentage * msg.capacity, rel=1e-6)
        assert msg.power_supply_status == 2                      # DISCHARGING


def test_an_aged_pack_reports_its_faded_capacity():
    with Simulation(load_world_text(world(drone("d1", "battery: {}, energy: {cycles: 250}")))) as sim:
        sim.run(duration=1.0)
        msg = sim.sensor("d1", "battery")
        # 500 cycles to 80 %: after 250 the pack holds 90 % of its design capacity
        assert msg.capacity == pytest.approx(0.9 * msg.design_capacity)


def test_odometry_is_ground_truth_with_the_twist_in_the_body_frame():
    with Simulation(load_world_text(world(drone("d1", "odometry: {}")))) as sim:
        sim.set_target("d1", 0.0, 0.0, 10.0, yaw_deg=90.0)
        sim.run(duration=8.0)
        sim.set_target("d1", 0.0, 60.0, 10.0, speed=5.0)         # fly north, nose first
        sim.run(duration=5.0)
        odo = sim.sensor("d1", "odometry")
        assert odo.header.frame_id == "d1/odom" and odo.child_frame_id == "d1/base_link"
        assert np.allclose(vec(odo.pose.pose.position), sim.position_enu_m("d1"), atol=0.2)
        assert odo.twist.twist.linear.x == pytest.approx(5.0, abs=0.3)      # forward in the body frame
        assert abs(odo.twist.twist.linear.y) < 0.3


def test_every_message_round_trips_through_cdr_with_nanosecond_stamps_and_design_frames():
    sensors = "imu: {}, gps: {}, battery: {rate_hz: 80.0}, odometry: {}"
    with Simulation(load_world_text(world(drone("d1", sensors)))) as sim:
        sim.step(3)                                           # t = 0.0125 s: imu, battery, odometry, gps due
        frames = {"imu": "d1/imu_link", "gps": "d1/gps_link", "battery": "d1/base_link", "odometry": "d1/odom"}
        topics = {"imu": "/d1/imu/data", "gps": "/d1/gps/fix", "battery": "/d1/battery", "odometry": "/d1/odom"}
        for key in frames:
            sample = sim.services.sensors.latest[("d1", key)]
            msg = sample.msg
            back = deserialize(serialize(msg), msg.__msgtype__)
            assert serialize(back) == serialize(msg), key
            assert msg.header.frame_id == frames[key] and sample.topic == topics[key]
            stamp_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            assert stamp_s == pytest.approx(sample.time_s, abs=1e-9)
        assert sim.sensor("d1", "battery").header.stamp.nanosec == 12_500_000
