"""OUTPUTS phase: per-vehicle CSV logs (docs/architecture.md §9), written at the world's log rate."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO

import esper
import numpy as np

from ..components.body import Identity
from ..components.mission import MissionRuntime
from ..frames import euler_rpy_from_quat_xyzw
from ..geodesy import GeodeticOrigin, LocalTangentPlane
from ..phases import Phase
from ..world import StepContext
from .car_state import DriveMode
from .fleet_system import FleetSystem
from .flight_state import FlightMode, LandedState, NavState

POSE_COLUMNS = ("time_s", "x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg", "lat_deg", "lon_deg",
                "alt_m", "vx_m_s", "vy_m_s", "vz_m_s", "speed_m_s")
FLIGHT_COLUMNS = ("mode", "nav_state", "landed_state", "thrust_fl_n", "thrust_fr_n", "thrust_br_n", "thrust_bl_n",
                  "thrust_total_n", "power_w", "energy_used_wh", "battery_wh", "soc_frac", "pack_voltage_v",
                  "pack_current_a", "remaining_time_s", "payload_kg", "mission_step", "mission_step_type")
CAR_COLUMNS = ("drive_mode", "throttle", "brake", "steer_deg", "speed_fwd_m_s", "speed_sp_m_s")


class TrajectoryLogSystem(FleetSystem):
    """Append one row per vehicle to ``<out_dir>/<vehicle>.csv`` every ``decimation`` steps.

    Phase: OUTPUTS (read-only). Reads: fleet pose and velocity. Rate: ``log_hz`` on the sim clock
    (every ``round(physics_hz / log_hz)`` steps), plus a first row at t = 0. Each batch is flushed so
    that an interrupted run keeps every row written so far. A vehicle spawned later gets its file
    when it first appears; a removed one's file stays open (and complete) until :meth:`close`.
    """

    phase = Phase.OUTPUTS
    order = 90
    requires = (Identity,)

    def __init__(self, out_dir: Path, decimation: int, origin: GeodeticOrigin) -> None:
        super().__init__()
        self.out_dir = Path(out_dir)
        self.decimation = max(1, int(decimation))
        self._ltp = LocalTangentPlane(origin)
        self._files: list[IO[str]] = []
        self._writers: list[csv.writer] = []
        self._kind: dict[int, str] = {}         # writer index -> entity kind (which extra columns)
        self._names: list[str] = []
        self._logged = np.empty(0, dtype=np.intp)   # fleet rows of the vehicles (not packages), ascending
        self._writer_idx: list[int] = []            # writer of each logged row
        self._entity_of: dict[str, int] = {}        # vehicle name -> entity (for its mission)
        self.paths: dict[str, Path] = {}

    def gather(self, ctx: StepContext) -> None:
        vehicles = [(int(row), int(ent), ident) for row, ent, ident in zip(self.rows, self.entities, self.components[0])
                    if ident.kind != "package"]
        for _, _, ident in sorted(vehicles, key=lambda v: v[2].name):     # new files in name order
            if ident.name in self.paths:
                continue
            path = self.out_dir / f"{ident.name}.csv"
            fh = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115 (closed in close())
            w = csv.writer(fh)
            extra = {"quadrotor": FLIGHT_COLUMNS, "car": CAR_COLUMNS}.get(ident.kind, ())
            w.writerow(POSE_COLUMNS + extra)
            self._kind[len(self._files)] = ident.kind
            self._names.append(ident.name)
            self.paths[ident.name] = path
            self._files.append(fh)
            self._writers.append(w)
        order = {name: i for i, name in enumerate(self.paths)}
        self._logged = np.array([row for row, _, _ in vehicles], dtype=np.intp)
        self._writer_idx = [order[ident.name] for _, _, ident in vehicles]
        self._entity_of = {ident.name: ent for _, ent, ident in vehicles}

    def write_rows(self, ctx: StepContext, time_s: float) -> None:
        """Write the current state of every vehicle, stamped ``time_s``."""
        if self.refresh(ctx):
            self._write(ctx, time_s)

    def update(self, ctx: StepContext) -> None:
        self._write(ctx, ctx.sim_time_s + ctx.dt_s)

    def process(self, ctx: StepContext) -> None:
        if (ctx.step + 1) % self.decimation == 0:
            super().process(ctx)

    def _write(self, ctx: StepContext, time_s: float) -> None:
        f = ctx.fleet
        r = self._logged
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
            rt = esper.try_component(self._entity_of[name], MissionRuntime)
            if rt is not None:
                step_type = rt.spec.steps[step].type
        return [FlightMode(int(f.flight_mode[row])).name.lower(), NavState(int(f.nav_state[row])).name.lower(),
                LandedState(int(f.landed_state[row])).name.lower(), *(f"{t:.4f}" for t in thrust),
                f"{thrust.sum():.4f}", f"{f.power_w[row]:.3f}", f"{f.energy_used_j[row] / 3600.0:.5f}",
                f"{f.energy_j[row] / 3600.0:.5f}", f"{f.soc_frac[row]:.6f}", f"{f.pack_voltage_v[row]:.4f}",
                f"{f.pack_current_a[row]:.4f}",
                f"{min(f.remaining_time_s[row], 1e9):.1f}", f"{f.payload_kg[row]:.3f}", str(step), step_type]

    @staticmethod
    def _car_columns(f, row: int) -> list[str]:
        return [DriveMode(int(f.drive_mode[row])).name.lower(), f"{f.car_throttle[row]:.4f}",
                f"{f.car_brake[row]:.4f}", f"{np.rad2deg(f.car_steer_rad[row]):.3f}",
                f"{f.car_speed_m_s[row]:.4f}", f"{f.car_speed_sp_m_s[row]:.4f}"]

    def close(self) -> None:
        for fh in self._files:
            fh.close()
        self._files.clear()
