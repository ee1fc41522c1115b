"""Fly one drone with MAVSDK-Python's native binding (mavsdk 4.x, ctypes; no mavsdk_server): connect,
wait for a home position, set the takeoff altitude, wait until armable, arm, take off, fly 2 s of
offboard attitude (8 deg nose down, its heading, the thrust that carries its weight), stop offboard
(HOLD), land, wait for the auto-disarm.
Usage: python mavsdk_native_flight.py UDP_PORT HOVER_THRUST   (the port the drone's API link sends to;
m g / (4 F_max) of the drone)
Prints one JSON line per step."""

import asyncio
import json
import math
import sys
import time

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import Attitude, OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

T0 = time.monotonic()


def log(step, **data):
    print(json.dumps({"step": step, "wall_s": round(time.monotonic() - T0, 2), **data}), flush=True)


async def until(get, pred, timeout_s=60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = await get()
        if pred(value):
            return value
        await asyncio.sleep(0.2)
    raise TimeoutError(f"{get.__name__} did not reach the expected value")


async def main(port: int, hover_thrust: float) -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=20.0)
        if system is None:
            raise TimeoutError("no autopilot found")
        action, telemetry, offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)
        home = await until(telemetry.home, lambda h: h.absolute_altitude_m == h.absolute_altitude_m)   # not NaN
        log("connected", system_id=await system.get_system_id(), home_alt_m=home.absolute_altitude_m)
        await action.set_takeoff_altitude(4.0)
        await until(telemetry.landed_state, lambda state: state.name == "ON_GROUND")   # settled after spawning
        await until(telemetry.health, lambda h: h.is_armable)      # and PX4's pre-arm checks pass
        await action.arm()
        await action.takeoff()
        pos = await until(telemetry.position, lambda p: p.relative_altitude_m > 3.5)
        log("took_off", relative_alt_m=pos.relative_altitude_m, in_air=await telemetry.in_air())
        heading = (await telemetry.heading()).heading_deg
        tilt = math.radians(8.0)
        await offboard.set_attitude(Attitude(0.0, -8.0, heading, hover_thrust / math.cos(tilt)))
        await offboard.start()
        mode = await until(telemetry.flight_mode, lambda m: m.name == "OFFBOARD", 10.0)
        await asyncio.sleep(2.0)
        v = await telemetry.velocity_ned()
        log("offboard_attitude", heading_deg=heading, mode=mode.name, vel_ned_m_s=[v.north_m_s, v.east_m_s, v.down_m_s])
        await offboard.stop()
        await action.land()
        await until(telemetry.armed, lambda armed: not armed, 90.0)
        pos = await telemetry.position()
        log("landed_and_disarmed", relative_alt_m=pos.relative_altitude_m)


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]), float(sys.argv[2])))
