"""OUTPUTS phase: per-vehicle CSV logs (docs/architecture.md §9), written at the world's log rate."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO

import esper
import numpy as np

from ..components.body import FleetSlot, Identity
from ..components.mission import MissionRuntime
from ..frames import euler_rpy_from_quat_xyzw
from ..geodesy import GeodeticOrigin, LocalTangentPlane
from ..phases import Phase
from ..world import StepContext
from .car_state import DriveMode, declare_car_arrays
from .flight_state import FlightMode, declare_flight_arrays

POSE_COLUMNS = ("time_s", "x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg", "lat_deg", "lon_deg",
                "alt_m", "vx_m_s", "vy_m_s", "vz_m_s", "speed_m_s")
FLIGHT_COLUMNS = ("mode", "thrust_fl_n", "thrust_fr_n", "thrust_br_n", "thrust_bl_n", "thrust_total_n", "power_w",
                  "energy_used_wh", "battery_wh", "soc_frac", "remaining_time_s", "payload_kg", "mission_step",
                  "mission_step_type")
CAR_COLUMNS = ("drive_mode", "throttle", "brake", "steer_deg", "speed_fwd_m_s", "speed_sp_m_s")


class TrajectoryLogSystem(esper.Processor):
    """Append one row per vehicle to ``<out_dir>/<vehicle>.csv`` every ``decimation`` steps.

    Phase: OUTPUTS (read-only). Reads: fleet pose and velocity. Rate: ``log_hz`` on the sim clock
    (every ``round(physics_hz / log_hz)`` steps), plus a first row at t = 0. Each batch is flushed so
    that an interrupted run keeps every row written so far.
    """

    phase = Phase.OUTPUTS
    order = 90

    def __init__(self, out_dir: Path, decimation: int, origin: GeodeticOrigin) -> None:
        self.out_dir = Path(out_dir)
        self.decimation = max(1, int(decimation))
        self._ltp = LocalTangentPlane(origin)
        self._files: list[IO[str]] = []
        self._writers: list[csv.writer] = []
        self._kind: dict[int, str] = {}         # writer index -> entity kind (which extra columns)
        self._names: list[str] = []
        self._rows = np.empty(0, dtype=np.intp)
        self._seen_version = -1
        self.paths: dict[str, Path] = {}

    def _gather(self) -> None:
        found = sorted(((ident.name, slot.row) for _, (ident, slot) in esper.get_components(Identity, FleetSlot)
                        if ident.kind != "package"))
        kinds = {ident.name: ident.kind for _, ident in esper.get_component(Identity)}
        self._mission_of = {ident.name: ent for ent, ident in esper.get_component(Identity)}
        new = [name for name, _ in found if name not in self.paths]
        for name in new:
            path = self.out_dir / f"{name}.csv"
            fh = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115 (closed in close())
            w = csv.writer(fh)
            extra = {"quadrotor": FLIGHT_COLUMNS, "car": CAR_COLUMNS}.get(kinds[name], ())
            w.writerow(POSE_COLUMNS + extra)
            self._kind[len(self._files)] = kinds[name]
            self._names.append(name)
            self.paths[name] = path
            self._files.append(fh)
            self._writers.append(w)
        order = {name: i for i, name in enumerate(self.paths)}
        by_writer = sorted((order[name], row) for name, row in found)
        self._writer_idx = [i for i, _ in by_writer]
        self._rows = np.array([r for _, r in by_writer], dtype=np.intp)

    def write_rows(self, ctx: StepContext, time_s: float) -> None:
        """Write the current state of every vehicle, stamped ``time_s``."""
        f = ctx.fleet
        if f.version != self._seen_version:
            declare_flight_arrays(f)
            declare_car_arrays(f)
            self._gather()
            self._seen_version = f.version
        r = self._rows
        if r.size == 0:
            return
        pos = f.pos_enu_m[r]
        vel = f.vel_enu_m_s[r]
        rpy_deg = np.rad2deg(np.stack(euler_rpy_from_quat_xyzw(f.quat_enu_flu_xyzw[r]), axis=-1))
        lat, lon, alt = self._ltp.to_geodetic(pos)
        speed = np.linalg.norm(vel, axis=1)
        for k, wi in enumerate(self._writer_idx):
            row = [f"{time_s:.4f}", *(f"{x:.4f}" for x in pos[k]), *(f"{a:.3f}" for a in rpy_deg[k]),
                   f"{lat[k]:.9f}", f"{lon[k]:.9f}", f"{alt[k]:.4f}", *(f"{v:.4f}" for v in vel[k]),
                   f"{speed[k]:.4f}"]
            kind = self._kind[wi]
            if kind == "quadrotor":
                row += self._flight_columns(f, int(r[k]), self._names[wi])
            elif kind == "car":
                row += self._car_columns(f, int(r[k]))
            self._writers[wi].writerow(row)
        for wi in set(self._writer_idx):
            self._files[wi].flush()

    def _flight_columns(self, f, row: int, name: str) -> list[str]:
        thrust = f.motor_thrust_n[row]
        step = int(f.mission_step[row])
        step_type = ""
        if step >= 0:
            rt = esper.try_component(self._mission_of[name], MissionRuntime)
            if rt is not None:
                step_type = rt.spec.steps[step].type
        return [FlightMode(int(f.flight_mode[row])).name.lower(), *(f"{t:.4f}" for t in thrust),
                f"{thrust.sum():.4f}", f"{f.power_w[row]:.3f}", f"{f.energy_used_j[row] / 3600.0:.5f}",
                f"{f.energy_j[row] / 3600.0:.5f}", f"{f.soc_frac[row]:.6f}",
                f"{min(f.remaining_time_s[row], 1e9):.1f}", f"{f.payload_kg[row]:.3f}", str(step), step_type]

    @staticmethod
    def _car_columns(f, row: int) -> list[str]:
        return [DriveMode(int(f.drive_mode[row])).name.lower(), f"{f.car_throttle[row]:.4f}",
                f"{f.car_brake[row]:.4f}", f"{np.rad2deg(f.car_steer_rad[row]):.3f}",
                f"{f.car_speed_m_s[row]:.4f}", f"{f.car_speed_sp_m_s[row]:.4f}"]

    def process(self, ctx: StepContext) -> None:
        if (ctx.step + 1) % self.decimation == 0:
            self.write_rows(ctx, ctx.sim_time_s + ctx.dt_s)

    def close(self) -> None:
        for fh in self._files:
            fh.close()
        self._files.clear()
