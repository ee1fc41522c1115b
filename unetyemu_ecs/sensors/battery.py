"""Battery: ``sensor_msgs/BatteryState`` of a drone's battery pack (``energy`` component).

Voltage and current are the pack's terminal values of the energy model (the LiPo equivalent
circuit sags under load; the ``ideal`` battery holds its nominal voltage); cell voltages are the
terminal voltage shared equally by the series cells; charge and capacity are in ampere-hours, the
capacity faded by the pack's cycles (``capacity``) next to the new pack's (``design_capacity``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

import esper
import numpy as np

from ..components.flight import EnergyModel
from ..config.limits import SensorRate
from ..phases import Phase
from ..world import StepContext
from .base import MountedSensor, SensorSpec, SensorSystemBase
from .messages import header, msg_type


@dataclass(frozen=True, kw_only=True)
class BatterySensor(SensorSpec):
    """World-file key ``battery`` (drones: it reads the ``energy`` model)."""

    rate_hz: SensorRate = 1.0                 # [Hz], config.limits


class BatterySystem(SensorSystemBase):
    """Every battery monitor that is due. Phase: SENSORS. Reads: pack voltage and current, state of charge."""

    phase = Phase.SENSORS
    order = 30
    spec_type = BatterySensor
    key = "battery"
    topic_suffix = "battery"
    link = "base_link"

    def measure(self, ctx: StepContext, due: list[MountedSensor], time_s: float) -> None:
        f = ctx.fleet
        for s in due:
            model = esper.component_for_entity(s.entity, EnergyModel)
            self.publish(ctx, s, time_s, build=partial(
                battery_message, time_s, s.frame_id, s.vehicle, float(f.pack_voltage_v[s.row]),
                float(f.pack_current_a[s.row]), model.cells_series, model.capacity_ah, model.design_capacity_ah,
                float(f.soc_frac[s.row]), bool(f.charging[s.row])))


def battery_message(time_s: float, frame_id: str, vehicle: str, voltage_v: float, current_a: float, cells: int,
                    capacity_ah: float, design_capacity_ah: float, soc_frac: float, charging: bool) -> Any:
    """The sensor_msgs/BatteryState of one reading (``current_a`` > 0 while discharging: ROS reports it negated)."""
    BatteryState = msg_type("sensor_msgs/msg/BatteryState")
    status = (BatteryState.POWER_SUPPLY_STATUS_FULL if soc_frac >= 1.0 and not charging else
              BatteryState.POWER_SUPPLY_STATUS_CHARGING if charging else
              BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    return BatteryState(
        header=header(time_s, frame_id), voltage=float(voltage_v), temperature=float("nan"), current=-float(current_a),
        charge=soc_frac * capacity_ah, capacity=float(capacity_ah), design_capacity=float(design_capacity_ah),
        percentage=soc_frac, power_supply_status=status,
        power_supply_health=(BatteryState.POWER_SUPPLY_HEALTH_DEAD if soc_frac <= 0.0
                             else BatteryState.POWER_SUPPLY_HEALTH_GOOD),
        power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO, present=True,
        cell_voltage=np.full(cells, voltage_v / cells, dtype=np.float32),
        cell_temperature=np.full(cells, np.nan, dtype=np.float32),
        location=vehicle, serial_number="")


__all__ = ["BatterySensor", "BatterySystem", "battery_message"]
