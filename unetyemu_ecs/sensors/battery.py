"""Battery: ``sensor_msgs/BatteryState`` of a drone's energy model (charge, current, percentage).

The energy model (:mod:`unetyemu_ecs.systems.energy`) works in watts and watt-hours; the message
speaks amperes and ampere-hours at the pack's nominal voltage (a constant-voltage pack: the model
has no discharge curve, and says so by reporting the nominal voltage).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Annotated, Any

import esper
import numpy as np

from ..components.flight import EnergyModel
from ..config.limits import SensorRate
from ..config.schema import Gt, Le
from ..phases import Phase
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import header, msg_type


@dataclass(frozen=True, kw_only=True)
class BatterySensor(SensorSpec):
    """World-file key ``battery`` (drones: it reads the ``energy`` model)."""

    rate_hz: SensorRate = 1.0                 # [Hz], config.limits
    # up to an 800 V electric-car pack (1000 V) of ~240 cells (256)
    nominal_voltage_v: Annotated[float, Gt(0.0), Le(1_000.0)] = 22.2     # 6S lithium-polymer pack
    cells: Annotated[int, Gt(0), Le(256)] = 6


class BatterySystem(SensorSystemBase):
    """Every battery monitor that is due. Phase: SENSORS. Reads: power, energy, state of charge."""

    phase = Phase.SENSORS
    order = 30
    spec_type = BatterySensor
    key = "battery"
    topic_suffix = "battery"
    link = "base_link"

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        f = ctx.fleet
        for s in due:
            spec: BatterySensor = s.spec
            model = esper.component_for_entity(s.entity, EnergyModel)
            charging = bool(f.charging[s.row])
            # ROS: current is negative while discharging
            power_w = float(f.charge_power_w[s.row]) if charging else -float(f.power_w[s.row])
            self.publish(ctx, s, time_s, build=partial(battery_message, time_s, s.frame_id, s.vehicle,
                                                       spec.nominal_voltage_v, spec.cells, model.battery_wh,
                                                       float(f.soc_frac[s.row]), float(f.energy_j[s.row]), power_w,
                                                       charging))


def battery_message(time_s: float, frame_id: str, vehicle: str, voltage_v: float, cells: int, capacity_wh: float,
                    soc_frac: float, energy_j: float, power_w: float, charging: bool) -> Any:
    """The sensor_msgs/BatteryState of one reading (``power_w`` > 0 while charging, < 0 while discharging)."""
    BatteryState = msg_type("sensor_msgs/msg/BatteryState")
    v = voltage_v
    status = (BatteryState.POWER_SUPPLY_STATUS_FULL if soc_frac >= 1.0 and not charging else
              BatteryState.POWER_SUPPLY_STATUS_CHARGING if charging else
              BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    return BatteryState(
        header=header(time_s, frame_id), voltage=float(v), temperature=float("nan"), current=power_w / v,
        charge=energy_j / 3600.0 / v, capacity=capacity_wh / v, design_capacity=capacity_wh / v, percentage=soc_frac,
        power_supply_status=status,
        power_supply_health=(BatteryState.POWER_SUPPLY_HEALTH_DEAD if soc_frac <= 0.0
                             else BatteryState.POWER_SUPPLY_HEALTH_GOOD),
        power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO, present=True,
        cell_voltage=np.full(cells, v / cells, dtype=np.float32),
        cell_temperature=np.full(cells, np.nan, dtype=np.float32),
        location=vehicle, serial_number="")


__all__ = ["BatterySensor", "BatterySystem", "battery_message"]
