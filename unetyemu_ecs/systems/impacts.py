"""STATE phase: report impacts, i.e. a vehicle or package starting to touch something while moving fast.

A crash into a building, a tree, a parked car or another drone is a rare event a user must know
about (the controllers may recover and the mission may still complete). Landings and resting
contacts are not impacts: an impact is a *new* contact pair whose relative speed just before first touch is
at least :data:`IMPACT_SPEED_M_S`. "Just before": PyBullet resolves a collision inside the step that
first reports it, so the velocities read back after that step are already the rebound; the monitor
keeps the previous step's velocities (the approach) for the test.
"""

from __future__ import annotations

from typing import Any

import esper
import numpy as np

from ..components.body import Identity
from ..phases import Phase
from ..scene.primitives import SceneClass, SceneLayout
from ..world import StepContext

# Relative speed at first contact above which a touch is an impact [m/s]: above any landing the
# flight stack flies (descents end slower than 1.5 m/s; a drone dropping onto the package it just
# set down touches at ~1.2 m/s) and the free-fall speed of a 20 cm drop.
IMPACT_SPEED_M_S = 2.0
IMPACT_REARM_S = 0.5        # a pair must stay apart this long before a new touch counts again [s]


class ImpactMonitorSystem(esper.Processor):
    """Turn new fast contacts into events and per-entity impact counts.

    A pair that keeps touching, or touches again within :data:`IMPACT_REARM_S` (a body bouncing
    or sliding along a wall), is one impact.

    Phase: STATE (after the readback, order 50). Reads: all PyBullet contact points (one call per
    step), fleet velocities. Writes: ``fleet.impacts`` (count per row), ``services.events`` (one
    line per impact naming both sides, the point and the speed).

    Not a :class:`~unetyemu_ecs.systems.fleet_system.FleetSystem`: it watches every body, whatever
    its components, and what it keeps per row (body id, name, last velocity) changes only when rows
    are allocated or freed, so ``fleet.version`` alone tells it when to look again.
    """

    phase = Phase.STATE
    order = 50

    def __init__(self, static_classes: dict[int, SceneClass], layout: SceneLayout) -> None:
        self.static_classes = dict(static_classes)
        self.layout = layout
        self._last_touch_s: dict[tuple[int, int], float] = {}   # pair -> sim time of its last contact [s]
        self._seen_version = -1
        self._row_of_body: dict[int, int] = {}
        self._name_of_row: dict[int, str] = {}
        self._vel_before = np.zeros((0, 3))      # fleet velocities at the end of the previous step [m/s]

    def _refresh(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = f.rows
        self._row_of_body = {int(f.body_id[r]): int(r) for r in rows}
        names = {ent: ident.name for ent, ident in esper.get_component(Identity)}
        self._name_of_row = {int(r): names.get(int(f.entity[r]), f"row {r}") for r in rows}
        self._seen_version = f.version
        self._vel_before = f.vel_enu_m_s.copy()

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        if f.version != self._seen_version:
            self._refresh(ctx)
        now: dict[tuple[int, int], tuple[float, float, float]] = {}
        for a, b, point in ctx.physics.contacts():
            key = (a, b) if a < b else (b, a)
            now.setdefault(key, point)
        t = ctx.sim_time_s + ctx.dt_s
        last = self._last_touch_s
        for key, point in now.items():
            if t - last.get(key, -np.inf) > IMPACT_REARM_S:
                self._report(ctx, key, point)
            last[key] = t
        if len(last) > 4 * len(now) + 64:        # forget pairs long apart (bounded memory)
            self._last_touch_s = {k: v for k, v in last.items() if t - v <= IMPACT_REARM_S}
        np.copyto(self._vel_before, f.vel_enu_m_s)

    def forget_motion(self, fleet: Any) -> None:
        """Judge the next contacts by the bodies' velocities now (after bodies were moved by hand: a
        vehicle put back at rest must not "hit" what it touches at the speed it had before)."""
        if self._vel_before.shape == fleet.vel_enu_m_s.shape:
            np.copyto(self._vel_before, fleet.vel_enu_m_s)

    def _velocity(self, body: int) -> np.ndarray:
        """Velocity [m/s] of ``body`` before this step (zero for static bodies)."""
        row = self._row_of_body.get(body)
        return np.zeros(3) if row is None else self._vel_before[row]

    def _describe(self, body: int, point: np.ndarray) -> str:
        row = self._row_of_body.get(body)
        if row is not None:
            return self._name_of_row[row]
        cls = self.static_classes.get(body)
        if cls is None:
            return f"body {body}"
        if cls == SceneClass.GROUND:
            return "the ground"
        obj, _ = self.layout.nearest_object(point, cls)
        return obj.name

    def _report(self, ctx: StepContext, pair: tuple[int, int], point_xyz: tuple[float, float, float]) -> None:
        a, b = pair
        speed = float(np.linalg.norm(self._velocity(a) - self._velocity(b)))
        if speed < IMPACT_SPEED_M_S:
            return
        point = np.asarray(point_xyz, dtype=float)
        movers = [body for body in pair if body in self._row_of_body]
        for body in movers:
            ctx.fleet.impacts[self._row_of_body[body]] += 1
        # told from the side that was moving faster (the one that hit)
        first = max(movers, key=lambda body: float(np.linalg.norm(self._velocity(body))))
        other = b if first == a else a
        where = ", ".join(f"{c:.1f}" for c in point)
        ctx.services.note(ctx.sim_time_s + ctx.dt_s, self._name_of_row[self._row_of_body[first]],
                          f"impact with {self._describe(other, point)} at {speed:.1f} m/s, ENU ({where}) m")


__all__ = ["IMPACT_SPEED_M_S", "ImpactMonitorSystem"]
