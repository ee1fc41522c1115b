"""A world system that makes a run fail at a chosen sim time, the three ways a real run goes wrong:

- ``raise``: a Python exception inside a step (a bug in a plugin);
- ``exit``: the process dies at once, as after a segfault or the out-of-memory killer;
- ``stall``: every step takes ``stall_s`` of wall time from then on (a run that would never end in time).

Used by the sweep tests (``systems: {fault: {at_s: 2.0, how: raise}}``); never in a real world.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Annotated, Literal

import esper

from unetyemu_ecs.plugin_api import Ge, Le, Phase, StepContext, SystemPlugin


@dataclass(frozen=True, kw_only=True)
class FaultConfig:
    at_s: Annotated[float, Ge(0.0), Le(604_800.0)] = 1.0       # sim time of the fault [s]
    how: Literal["raise", "exit", "stall"] = "raise"
    stall_s: Annotated[float, Ge(0.0), Le(10.0)] = 0.05        # wall time per step once stalled [s]


class FaultSystem(esper.Processor):
    phase = Phase.ACTUATE
    order = 90

    def __init__(self, config: FaultConfig) -> None:
        self.config = config

    def process(self, ctx: StepContext) -> None:
        cfg = self.config
        if ctx.sim_time_s < cfg.at_s:
            return
        if cfg.how == "raise":
            raise RuntimeError(f"injected fault at t={ctx.sim_time_s:.2f} s")
        if cfg.how == "exit":
            os._exit(3)
        time.sleep(cfg.stall_s)


FAULT = SystemPlugin(system=FaultSystem, config=FaultConfig, summary="fails the run on purpose (tests only)")
