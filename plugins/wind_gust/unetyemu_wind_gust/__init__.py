"""Wind gust world system: uniform wind = mean + sinusoidal gust + seeded Gauss-Markov turbulence.

The wind velocity at time t (ENU, horizontal direction ``toward_deg``, 0 = east, CCW)::

    w(t) = (mean_speed_m_s + gust_amplitude_m_s * sin(2 pi t / gust_period_s)) * d + vertical + n(t)

where ``n`` is first-order Gauss-Markov noise with standard deviation ``turbulence_std_m_s`` and
correlation time ``turbulence_tau_s`` (drawn from the simulation's seeded RNG, so runs repeat).
It is written to ``fleet.wind_enu_m_s`` for every body in ACTUATE before drag is computed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import esper
import numpy as np

try:
    from unetyemu_ecs.plugin_api import Ge, Le, Phase, StepContext, SystemPlugin
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("unetyemu-wind-gust is a plugin of the unetyemu_ecs simulator: install it into the "
                      "environment that has unetyemu_ecs (.venv/bin/pip install ./plugins/wind_gust from the "
                      f"simulator's repository) ({exc})") from exc


@dataclass(frozen=True, kw_only=True)
class WindGustConfig:
    """World-file parameters of the wind (``systems: {wind_gust: {...}}``)."""

    # bounds: winds past 50 m/s (a category-3 hurricane) are outside anything a drone or car flies or
    # drives in; a gust period below 0.1 s is turbulence, not a gust
    mean_speed_m_s: Annotated[float, Ge(0.0), Le(50.0)] = 5.0
    toward_deg: Annotated[float, Ge(-360.0), Le(360.0)] = 0.0  # ENU direction the wind blows to
    gust_amplitude_m_s: Annotated[float, Ge(0.0), Le(50.0)] = 2.0
    gust_period_s: Annotated[float, Ge(0.1), Le(3600.0)] = 8.0
    vertical_m_s: Annotated[float, Ge(-20.0), Le(20.0)] = 0.0  # up positive
    turbulence_std_m_s: Annotated[float, Ge(0.0), Le(20.0)] = 0.0
    turbulence_tau_s: Annotated[float, Ge(0.01), Le(3600.0)] = 2.0


def wind_enu_m_s(cfg: WindGustConfig, t_s: float, turbulence_enu_m_s: np.ndarray) -> np.ndarray:
    """Return the wind velocity (3,) [m/s] in ENU at time ``t_s`` given the current turbulence (3,)."""
    heading = np.deg2rad(cfg.toward_deg)
    speed = cfg.mean_speed_m_s + cfg.gust_amplitude_m_s * np.sin(2.0 * np.pi * t_s / cfg.gust_period_s)
    return np.array([speed * np.cos(heading), speed * np.sin(heading), cfg.vertical_m_s]) + turbulence_enu_m_s


class WindGustSystem(esper.Processor):
    """Write the wind at every body.

    Phase: ACTUATE, order 10 (before drag). Writes: fleet.wind_enu_m_s (all rows).
    """

    phase = Phase.ACTUATE
    order = 10

    def __init__(self, config: WindGustConfig) -> None:
        self.config = config
        self.turbulence_enu_m_s = np.zeros(3)

    def process(self, ctx: StepContext) -> None:
        cfg = self.config
        if cfg.turbulence_std_m_s > 0.0:
            a = np.exp(-ctx.dt_s / cfg.turbulence_tau_s)
            self.turbulence_enu_m_s = (a * self.turbulence_enu_m_s
                                       + cfg.turbulence_std_m_s * np.sqrt(1.0 - a * a) * ctx.rng.standard_normal(3))
        rows = ctx.fleet.rows
        if rows.size:
            ctx.fleet.wind_enu_m_s[rows] = wind_enu_m_s(cfg, ctx.sim_time_s, self.turbulence_enu_m_s)


WIND_GUST = SystemPlugin(system=WindGustSystem, config=WindGustConfig,
                         summary="uniform wind with sinusoidal gusts and seeded turbulence")
