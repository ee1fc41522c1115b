"""World files of the benchmarks and the stress script (one place, so both measure the same scenes)."""

from __future__ import annotations


def city_with_lidar_drones(n: int) -> str:
    """``n`` drones 15 m above the default city's north-south streets (x = -72, 0, 72), each with a 360x16
    LiDAR tilted 15 deg down (10 Hz), so that the scans see streets and facades."""
    lines = ["world: {name: bench_lidar, physics_hz: 240, seed: 42}", "scene: {generator: urban}", "vehicles:"]
    for i in range(n):
        x, y = -72.0 + 72.0 * (i % 3), -130.0 + 260.0 * (i // 3) / max((n - 1) // 3, 1)
        lines.append(f"  - {{name: d{i}, type: quadrotor, preset: medium, pose: {{position_m: [{x:.1f}, {y:.1f}, 15.0]}},"
                     f" components: {{lidar: {{vertical_center_deg: -15.0}}}}}}")
    return "\n".join(lines) + "\n"


__all__ = ["city_with_lidar_drones"]
