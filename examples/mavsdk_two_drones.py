"""Fly two simulated drones at once with MAVSDK-Python, exactly as you would fly two PX4 SITL instances.

Start a simulation with MAVLink endpoints first (every drone gets one with ``--mavlink``), in real time:

    unetyemu run worlds/mavlink_pair.yaml --duration 600 &
    python examples/mavsdk_two_drones.py --drones 2

Drone i listens on UDP 127.0.0.1:14580+i and sends to 14540+i (PX4 SITL's ports), so each MAVSDK
``System`` connects with ``udpin://127.0.0.1:14540+i``; each gets its own mavsdk_server
(gRPC port 50051+i). Each drone, concurrently: waits for a healthy position estimate, arms, takes
off, flies to a point, runs a four-waypoint mission with speed changes ended by RTL (which lands),
takes off again, flies offboard (NED position, NED velocity, body velocity with a yaw rate), lands
and disarms. What each drone did is printed as one JSON line per step (``--log FILE`` writes them
to a file too), so a test can compare it with the simulation's own state.

Needs ``pip install "mavsdk<4"`` (3.x, the gRPC ``System()`` API; with MAVSDK-Python 4.x install
``mavsdk-grpc`` and change the import to ``import mavsdk_grpc as mavsdk``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
import time
from typing import Any

from mavsdk import System
from mavsdk.mission import MissionItem, MissionPlan
from mavsdk.offboard import PositionNedYaw, VelocityBodyYawspeed, VelocityNedYaw

API_REMOTE_BASE = 14540      # drone i's API link sends to 14540+i (PX4 SITL)
GRPC_BASE = 50051            # one mavsdk_server per drone: gRPC port 50051+i
STEP_TIMEOUT_S = 90.0        # wall-clock limit of any one step


class FlightLog:
    """One JSON line per step: drone, step, wall time, and what was measured."""

    def __init__(self, path: str | None) -> None:
        self._file = open(path, "a", encoding="utf-8") if path else None
        self._t0 = time.monotonic()

    def __call__(self, drone: int, step: str, **data: Any) -> None:
        line = json.dumps({"drone": drone, "step": step, "wall_s": round(time.monotonic() - self._t0, 2), **data})
        print(line, flush=True)
        if self._file is not None:
            self._file.write(line + "\n")
            self._file.flush()


async def first(stream, predicate=lambda _: True, timeout_s: float = STEP_TIMEOUT_S):
    """The first item of a MAVSDK telemetry stream that satisfies ``predicate``."""

    async def scan():
        async for item in stream:
            if predicate(item):
                return item

    return await asyncio.wait_for(scan(), timeout_s)


async def ned_position(drone: System) -> tuple[float, float, float]:
    pv = await first(drone.telemetry.position_velocity_ned())
    return pv.position.north_m, pv.position.east_m, pv.position.down_m


async def heading_deg(drone: System) -> float:
    return (await first(drone.telemetry.heading())).heading_deg


async def fly(i: int, log: FlightLog, udp_base: int, grpc_base: int) -> None:
    drone = System(port=grpc_base + i)
    await drone.connect(system_address=f"udpin://127.0.0.1:{udp_base + i}")
    await first(drone.core.connection_state(), lambda s: s.is_connected)
    await first(drone.telemetry.health(), lambda h: h.is_global_position_ok and h.is_home_position_ok)
    home = await first(drone.telemetry.home())
    log(i, "healthy", home_lat=home.latitude_deg, home_lon=home.longitude_deg, home_alt_m=home.absolute_altitude_m)

    await drone.action.set_takeoff_altitude(5.0)
    await drone.action.set_return_to_launch_altitude(15.0)
    await drone.action.arm()
    await drone.action.takeoff()
    await first(drone.telemetry.in_air(), bool)
    pos = await first(drone.telemetry.position(), lambda p: p.relative_altitude_m > 4.5)
    log(i, "takeoff", relative_alt_m=pos.relative_altitude_m, mode=str(await first(drone.telemetry.flight_mode())))

    # goto: 20 m north of home, 8 m up (AMSL altitude, as MAVLink DO_REPOSITION wants it)
    north_deg = 20.0 / 111_320.0
    target = (home.latitude_deg + north_deg, home.longitude_deg, home.absolute_altitude_m + 8.0)
    await drone.action.goto_location(*target, 0.0)
    await first(drone.telemetry.position_velocity_ned(),
                lambda pv: abs(pv.position.north_m - 20.0) < 1.0 and abs(pv.position.down_m + 8.0) < 1.0)
    log(i, "goto", ned_m=await ned_position(drone))

    # a four-waypoint square with a different speed on each leg, then RTL (which lands)
    legs = [(20.0, 20.0, 4.0), (0.0, 20.0, 6.0), (0.0, 0.0, 3.0), (10.0, 0.0, 5.0)]     # north, east [m], speed
    items = [MissionItem(home.latitude_deg + n / 111_320.0,
                         home.longitude_deg + e / (111_320.0 * math.cos(math.radians(home.latitude_deg))),
                         10.0, v, True, float("nan"), float("nan"), MissionItem.CameraAction.NONE,
                         float("nan"), float("nan"), 1.0, float("nan"), float("nan"), MissionItem.VehicleAction.NONE)
             for n, e, v in legs]
    await drone.mission.set_return_to_launch_after_mission(True)
    await drone.mission.upload_mission(MissionPlan(items))
    await drone.mission.start_mission()
    await first(drone.mission.mission_progress(), lambda p: p.total > 0 and p.current == p.total, 240.0)
    log(i, "mission_done")
    await first(drone.telemetry.landed_state(), lambda s: s.name == "ON_GROUND", 240.0)
    await first(drone.telemetry.armed(), lambda armed: not armed, 60.0)
    log(i, "rtl_landed", ned_m=await ned_position(drone))

    # offboard: position, NED velocity, body velocity with a yaw rate
    await drone.action.arm()
    await drone.action.takeoff()
    await first(drone.telemetry.position(), lambda p: p.relative_altitude_m > 4.5)
    north, east, down = await ned_position(drone)
    await drone.offboard.set_position_ned(PositionNedYaw(north, east, down, 0.0))
    await drone.offboard.start()
    await drone.offboard.set_position_ned(PositionNedYaw(5.0, 5.0, -6.0, 90.0))
    await first(drone.telemetry.position_velocity_ned(),
                lambda pv: math.dist((pv.position.north_m, pv.position.east_m, pv.position.down_m), (5, 5, -6)) < 0.7)
    log(i, "offboard_position", ned_m=await ned_position(drone), heading_deg=await heading_deg(drone))
    await drone.offboard.set_velocity_ned(VelocityNedYaw(0.0, 2.0, 0.0, 90.0))      # 2 m/s east
    await asyncio.sleep(3.0)
    vel = (await first(drone.telemetry.velocity_ned()))
    log(i, "offboard_velocity_ned", vel_ned_m_s=(vel.north_m_s, vel.east_m_s, vel.down_m_s))
    before = await heading_deg(drone)
    await drone.offboard.set_velocity_body(VelocityBodyYawspeed(1.0, 0.0, 0.0, 30.0))   # forward, turning right
    await asyncio.sleep(4.0)
    after = await heading_deg(drone)
    log(i, "offboard_velocity_body", heading_before_deg=before, heading_after_deg=after)
    await drone.offboard.set_velocity_body(VelocityBodyYawspeed(0.0, 0.0, 0.0, 0.0))
    await drone.offboard.stop()

    await drone.action.land()
    await first(drone.telemetry.landed_state(), lambda s: s.name == "ON_GROUND", 120.0)
    await first(drone.telemetry.armed(), lambda armed: not armed, 60.0)
    log(i, "landed", ned_m=await ned_position(drone))


async def main_async(n: int, log: FlightLog, udp_base: int, grpc_base: int) -> None:
    await asyncio.gather(*(fly(i, log, udp_base, grpc_base) for i in range(n)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, default=2, help="how many drones to fly (MAVLink instances 0..N-1)")
    parser.add_argument("--log", help="also append the JSON lines to this file")
    parser.add_argument("--udp-base", type=int, default=API_REMOTE_BASE,
                        help="drone i's API link sends to this port + i (the mavlink component's api_remote_base)")
    parser.add_argument("--grpc-base", type=int, default=GRPC_BASE, help="mavsdk_server of drone i on this port + i")
    args = parser.parse_args(argv)
    if not 1 <= args.drones <= 10:
        parser.error(f"--drones must be in [1, 10], got {args.drones}")
    for name in ("udp_base", "grpc_base"):
        if not 1024 <= getattr(args, name) <= 65535 - args.drones:
            parser.error(f"--{name.replace('_', '-')} must be in [1024, {65535 - args.drones}], got {getattr(args, name)}")
    asyncio.run(main_async(args.drones, FlightLog(args.log), args.udp_base, args.grpc_base))
    return 0


if __name__ == "__main__":
    sys.exit(main())
