"""ACTUATE phase: the world's wind at every body (``world.wind`` in the world file).

``w = mean + sum of gusts(t) + Dryden turbulence``, ENU [m/s]:

- mean: ``speed_m_s`` toward ``toward_deg`` (ENU, 0 = east, counter-clockwise) and ``vertical_m_s``;
- gusts: MIL-F-8785C "1 - cosine" gusts (:func:`..control.dryden.gust_enu_m_s`), the same for
  every body (a front sweeping the whole world at once);
- turbulence: the low-altitude Dryden model (:mod:`..control.dryden`), one set of forming
  filters per body, driven by a generator seeded from the world's seed (so a run repeats, and
  adding a sensor does not change the wind), at the body's height above the ground plane.

It is written to ``fleet.wind_enu_m_s`` before the drag and energy systems read it: bodies feel it
through their ``aero_drag`` (drones, packages, cars) and rotors through their inflow; no sensor
sees it directly.
"""

from __future__ import annotations

import esper
import numpy as np

from ..control.dryden import DrydenParams, dryden_stationary_state, dryden_step, gust_enu_m_s
from ..phases import Phase
from ..world import StepContext

WIND_SEED_SALT = 0x57494E44       # "WIND": the wind's own stream of the world's seed


def mean_wind_enu_m_s(speed_m_s: float, toward_deg: float, vertical_m_s: float) -> np.ndarray:
    """The mean wind vector (3,) [m/s], ENU, blowing toward ``toward_deg`` (0 = east, counter-clockwise)."""
    heading = np.deg2rad(toward_deg)
    return np.array([speed_m_s * np.cos(heading), speed_m_s * np.sin(heading), vertical_m_s])


class WindFieldSystem(esper.Processor):
    """Write the wind at every body. Phase: ACTUATE, order 10 (before drag and rotors).

    Reads: fleet.pos_enu_m, vel_enu_m_s, entity. Writes: fleet.wind_enu_m_s (every active row).
    """

    phase = Phase.ACTUATE
    order = 10

    def __init__(self, spec, seed: int) -> None:
        self.spec = spec
        self.mean_enu_m_s = mean_wind_enu_m_s(spec.speed_m_s, spec.toward_deg, spec.vertical_m_s)
        self._gusts = [(g.start_s, g.peak_m_s, g.rise_time_s,
                        np.array([0.0, 0.0, 1.0]) if g.vertical else mean_wind_enu_m_s(1.0, g.toward_deg, 0.0))
                       for g in spec.gusts]
        self._turbulence = DrydenParams(wind_speed_20ft_m_s=spec.turbulence_w20_m_s) \
            if spec.turbulence_w20_m_s > 0.0 else None
        self._rng = np.random.default_rng([int(seed), WIND_SEED_SALT])
        self._version = -1
        self._state = np.zeros((0, 5))                 # Dryden filter states of the active rows, in row order
        self._entities: list[int] = []                 # the entity of each state row
        self._state_of: dict[int, np.ndarray] = {}     # entity -> its filter state (while the rows change)

    def _rows_changed(self, fleet) -> None:
        self._state_of = dict(zip(self._entities, self._state))    # keep every body's turbulence
        rows = np.arange(fleet.capacity)[fleet.active]
        entities = fleet.entity[rows].tolist()
        new = [e for e in entities if e not in self._state_of]
        if new:
            for e, s in zip(new, dryden_stationary_state(len(new), self._rng)):
                self._state_of[e] = s
        self._state_of = {e: self._state_of[e] for e in entities}
        self._state = np.array([self._state_of[e] for e in entities]).reshape(-1, 5)
        self._entities = entities
        self._version = fleet.version

    def process(self, ctx: StepContext) -> None:
        f = ctx.fleet
        rows = f.active
        t = ctx.sim_time_s
        wind = self.mean_enu_m_s
        for start, peak, rise, direction in self._gusts:
            if start <= t <= start + 2.0 * rise:
                wind = wind + gust_enu_m_s(t, start, peak, rise, direction)
        if self._turbulence is None:
            f.wind_enu_m_s[rows] = wind
            return
        if f.version != self._version:
            self._rows_changed(f)
        m = self._state.shape[0]
        if m == 0:
            return
        mean = np.broadcast_to(wind, (m, 3))
        self._state, turbulence = dryden_step(self._state, np.maximum(f.pos_enu_m[rows, 2], 0.0), mean,
                                              f.vel_enu_m_s[rows], ctx.dt_s, self._rng, self._turbulence)
        f.wind_enu_m_s[rows] = mean + turbulence
