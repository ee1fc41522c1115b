"""Equivalent-circuit (Thevenin, one RC pair) model of a lithium-polymer drone pack, vectorised over M packs.

Per cell: open-circuit voltage OCV(SOC) in series with an ohmic resistance R0 and one RC pair (R1 || C1).
A pack of ``cells_series`` identical cells multiplies OCV, R0 and R1 by the cell count and divides C1 by
it (tau1 = R1 C1 is the cell's). Parallel strings are folded into the cell: a cell of capacity Q stands
for Q / Q_ref reference cells in parallel, so R scales as Q_ref / Q and C as Q / Q_ref (tau unchanged).

- OCV(SOC): Chen & Rincon-Mora, "Accurate electrical battery model capable of predicting runtime and
  I-V performance", IEEE Trans. Energy Conversion 21(2):504-511, 2006, fitted on a TCL PL-383562
  850 mAh Li-ion polymer cell:  V_oc = -1.031 e^(-35 SOC) + 3.685 + 0.2156 SOC - 0.1178 SOC^2 + 0.3201 SOC^3.
  The fit reaches 4.10 V at SOC 1 (not the 4.20 V charge voltage) and 2.65 V at SOC 0.
- RC pair: the same paper's short-transient pair at high SOC (their constant terms, valid above SOC ~0.2):
  R1 / R_series = 46.69 / 74.46 mOhm and tau1 = 46.69 mOhm * 703.6 F = 32.9 s. Their long-transient pair
  (tau ~220 s) is left out.
- R0, capacity, cells, C rating, cut-off and cycle life: see ``LipoPackParams``.

Currents are positive when the pack discharges. ``soc_frac`` is the charge left as a fraction of the
effective capacity ``capacity_ah * soh_frac``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, NamedTuple

import numpy as np

from ..config.schema import Ge, Gt, Le

# Chen & Rincon-Mora 2006, 0.85 Ah TCL PL-383562 cell at high SOC: R_series, short-transient R and C
CHEN_R0_OHM = 0.07446
CHEN_R1_OHM = 0.04669
CHEN_C1_F = 703.6
_OCV_EXP_V, _OCV_EXP_RATE = -1.031, -35.0
_OCV_POLY_V = (3.685, 0.2156, -0.1178, 0.3201)   # coefficients of SOC^0..SOC^3 [V]


@dataclass(frozen=True, kw_only=True)
class LipoPackParams:
    """A Tattu (Gens ace) 22000 mAh 22.2 V 25C 6S1P UAV LiPo pack, per cell unless the name says pack.

    Sources:
    - 22.0 Ah, 6S, 3.7 V/cell nominal (22.2 V), 25C continuous: the product's name and rating
      (Gens ace / Tattu, https://genstattu.com/tattu-plus-25c-22000mah-6s1p-xt90-smart-lipo-battery.html).
      Its 488 Wh nominal is close to the simulator's 500 Wh default.
    - 3.5 V/cell cut-off under load: Gens ace / Tattu user manual, "For Tattu series batteries which are used
      for Unmanned Aircraft system, The recommended cut off voltage is 3.5V per cell"
      (https://www.manualshelf.com/manual/gens-ace/gea68006s10e5/user-manual-english.html).
    - 4.20 V/cell charge voltage: the LiCoO2 LiPo standard (6S full = 25.2 V).
    - 500 cycles to 80 % capacity: the pack page gives no cycle life; FMA Direct's LiPo Handbook vol. 2 p. 8
      (quoted at http://www.popularrc.com/) defines end of life as 80 % of rated capacity and gives about
      500 cycles at half the rated current; a LiPo maker's note says the same ("After 500 cycles ...
      approximately 80% of capacity", http://www.exa.com.tw/hot_240366.html). Fade is linear in cycles.
    - R0: the pack page gives no internal resistance; 1 mOhm/cell is the typical LiPo value of S. D. Prior,
      "Lithium Polymer Battery Power Supply" (CRC Press, doi:10.1201/9780429428364-2). Chen & Rincon-Mora's
      0.85 Ah consumer cell scaled to 22 Ah by parallel equivalence would give 2.9 mOhm and cut a 70 A hover
      off at 3.5 V/cell with 58 % of the charge left. R1 and tau1 follow Chen's ratio R1 / R0 = 0.627 and
      tau1 = 32.9 s (module docstring).
    """

    # Ranges: 1-24 cells in series; up to 1000 Ah; resistances within 1 Ohm per cell; tau1 within 3 h
    cells_series: Annotated[int, Ge(1), Le(24)] = 6
    capacity_ah: Annotated[float, Gt(0.0), Le(1_000.0)] = 22.0
    cell_nominal_v: Annotated[float, Gt(0.0), Le(5.0)] = 3.7
    cell_full_v: Annotated[float, Gt(0.0), Le(5.0)] = 4.2
    cell_cutoff_v: Annotated[float, Gt(0.0), Le(5.0)] = 3.5
    lim_discharge_c: Annotated[float, Gt(0.0), Le(500.0)] = 25.0         # [1/h] continuous current / capacity
    r0_cell_ohm: Annotated[float, Ge(0.0), Le(1.0)] = 1.0e-3
    r1_cell_ohm: Annotated[float, Gt(0.0), Le(1.0)] = 1.0e-3 * CHEN_R1_OHM / CHEN_R0_OHM    # 0.627 mOhm
    tau1_s: Annotated[float, Gt(0.0), Le(1e4)] = CHEN_R1_OHM * CHEN_C1_F                    # 32.85 s
    cycle_life: Annotated[float, Gt(0.0), Le(1e5)] = 500.0               # equivalent full cycles to eol
    eol_capacity_frac: Annotated[float, Ge(0.0), Le(1.0)] = 0.8          # capacity left after cycle_life

    @property
    def r0_pack_ohm(self) -> float:
        return self.cells_series * self.r0_cell_ohm

    @property
    def r1_pack_ohm(self) -> float:
        return self.cells_series * self.r1_cell_ohm

    @property
    def c1_cell_f(self) -> float:
        return self.tau1_s / self.r1_cell_ohm

    @property
    def lim_discharge_a(self) -> float:
        return self.lim_discharge_c * self.capacity_ah

    @property
    def energy_nominal_wh(self) -> float:
        return self.cells_series * self.cell_nominal_v * self.capacity_ah


class PackStep(NamedTuple):
    """State after ``step_pack``; each (M,)."""

    soc_frac: np.ndarray    # [0, 1] of the effective capacity
    v_rc_v: np.ndarray      # RC-pair voltage of the pack [V]
    terminal_v: np.ndarray  # pack terminal voltage at the end of the step [V]
    current_a: np.ndarray   # the current held over the step, + = discharge [A]


def cell_ocv_v(soc_frac: np.ndarray) -> np.ndarray:
    """Open-circuit voltage of one cell [V] at ``soc_frac`` (any shape, clipped to [0, 1]); Chen 2006."""
    return _ocv_of_clipped_v(*clipped_soc_and_exp(soc_frac))


def _cell_ocv_integral_v(soc_frac: np.ndarray) -> np.ndarray:
    """``int_0^soc OCV(s) ds`` [V] (times capacity in Ah: open-circuit energy in Wh)."""
    return _ocv_integral_of_clipped_v(*clipped_soc_and_exp(soc_frac))


def cell_ocv_and_integral_v(soc_frac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cell_ocv_v` and ``int_0^soc OCV(s) ds`` [V] at ``soc_frac`` at once (one exponential for both)."""
    s, exp_term = clipped_soc_and_exp(soc_frac)
    return _ocv_of_clipped_v(s, exp_term), _ocv_integral_of_clipped_v(s, exp_term)


def clipped_soc_and_exp(soc_frac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The SOC clipped to [0, 1] and the OCV fit's ``e^(-35 s)`` at it: what the OCV and its integral share."""
    s = np.minimum(np.maximum(soc_frac, 0.0), 1.0)
    return s, np.exp(_OCV_EXP_RATE * s)


def _ocv_of_clipped_v(s: np.ndarray, exp_term: np.ndarray) -> np.ndarray:
    """OCV [V] at the clipped SOC ``s`` given ``exp_term = e^(-35 s)``."""
    c0, c1, c2, c3 = _OCV_POLY_V
    return _OCV_EXP_V * exp_term + c0 + s * (c1 + s * (c2 + s * c3))


def _ocv_integral_of_clipped_v(s: np.ndarray, exp_term: np.ndarray) -> np.ndarray:
    """``int_0^s OCV`` [V] at the clipped SOC ``s`` given ``exp_term = e^(-35 s)``."""
    c0, c1, c2, c3 = _OCV_POLY_V
    exp_part = _OCV_EXP_V / _OCV_EXP_RATE * (exp_term - 1.0)
    return exp_part + s * (c0 + s * (c1 / 2 + s * (c2 / 3 + s * c3 / 4)))


def pack_terminal_v(soc_frac: np.ndarray, v_rc_v: np.ndarray, current_a: np.ndarray, r0_pack_ohm: np.ndarray,
                    cells_series: np.ndarray) -> np.ndarray:
    """Terminal voltage ``V = cells OCV(SOC) - v_rc - I R0`` [V], (M,); + current = discharge."""
    return terminal_from_ocv_v(cells_series * cell_ocv_v(soc_frac), v_rc_v, current_a, r0_pack_ohm)


def terminal_from_ocv_v(ocv_pack_v: np.ndarray, v_rc_v: np.ndarray, current_a: np.ndarray,
                        r0_pack_ohm: np.ndarray) -> np.ndarray:
    """Terminal voltage ``V = OCV_pack - v_rc - I R0`` [V] from the pack's open-circuit voltage; + current = discharge."""
    return ocv_pack_v - v_rc_v - current_a * r0_pack_ohm


def pack_current_for_power_a(power_w: np.ndarray, ocv_pack_v: np.ndarray, v_rc_v: np.ndarray,
                             r0_pack_ohm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Current [A] for a terminal power ``P`` [W] (+ = drawn, - = charger), and a power-limited flag.

    Solves ``P = (E - I R0) I`` with ``E = OCV - v_rc`` (> 0) for its smaller root, written as
    ``I = 2P / (E + sqrt(E^2 - 4 R0 P))`` so that R0 = 0 gives ``P / E``. Where ``P > E^2 / (4 R0)`` the
    pack cannot deliver P: the current is that of its maximum-power point ``E / (2 R0)`` and the flag is set.
    All (M,), or scalars (arithmetic only: kernels compile it, :mod:`.compiled`).
    """
    e_v = ocv_pack_v - v_rc_v
    disc_v2 = e_v * e_v - 4.0 * r0_pack_ohm * power_w
    root = 2.0 * power_w / (e_v + np.sqrt(np.maximum(disc_v2, 0.0)))
    # the smaller root never exceeds the maximum-power current E / (2 R0); where there is no root the clamped
    # formula gives more than it, so the smaller of the two is the answer either way (R0 = 0: no limit)
    at_max = e_v / np.maximum(2.0 * r0_pack_ohm, 1e-300)
    return np.minimum(root, at_max), disc_v2 < 0.0


def step_pack(soc_frac: np.ndarray, v_rc_v: np.ndarray, current_a: np.ndarray, dt_s: float,
              capacity_eff_ah: np.ndarray, r0_pack_ohm: np.ndarray, r1_pack_ohm: np.ndarray,
              tau1_s: np.ndarray, cells_series: np.ndarray) -> PackStep:
    """Advance M packs by ``dt_s`` holding ``current_a`` (+ = discharge, - = charge) over the step.

    SOC by coulomb counting on ``capacity_eff_ah = capacity_ah * soh_frac``, kept in [0, 1]; v_rc by the
    exact solution of ``dv/dt = -v / (R1 C1) + I / C1``: ``v' = v e^(-dt/tau) + I R1 (1 - e^(-dt/tau))``.
    Parameters are (M,) arrays or scalars; the terminal voltage is taken at the end of the step.
    """
    decay, rise = rc_decay(dt_s, tau1_s)
    soc, v_rc = advance_pack(soc_frac, v_rc_v, current_a, dt_s, 3600.0 * capacity_eff_ah, decay, rise, r1_pack_ohm)
    terminal = pack_terminal_v(soc, v_rc, current_a, r0_pack_ohm, cells_series)
    current = current_a if np.shape(current_a) == soc.shape else np.broadcast_to(current_a, soc.shape)
    return PackStep(soc, v_rc, terminal, np.asarray(current, dtype=float))


def rc_decay(dt_s: float, tau1_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The RC pair's decay ``e^(-dt/tau)`` over a step of ``dt_s`` and its complement ``1 - e^(-dt/tau)``."""
    decay = np.exp(-dt_s / tau1_s)
    return decay, 1.0 - decay


def advance_pack(soc_frac: np.ndarray, v_rc_v: np.ndarray, current_a: np.ndarray, dt_s: float,
                 capacity_eff_as: np.ndarray, decay: np.ndarray, rise: np.ndarray,
                 r1_pack_ohm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SOC and RC-pair voltage [V] after ``dt_s`` holding ``current_a``: :func:`step_pack` without the terminal
    voltage, with the effective capacity in ampere-seconds ``capacity_eff_as = 3600 capacity_eff_ah`` and the
    RC pair's ``decay, rise`` of :func:`rc_decay` given (constants a caller can keep between steps)."""
    soc = np.minimum(np.maximum(soc_frac - current_a * dt_s / capacity_eff_as, 0.0), 1.0)
    v_rc = v_rc_v * decay + current_a * r1_pack_ohm * rise
    return soc, v_rc


def pack_cut_off(terminal_v: np.ndarray, soc_frac: np.ndarray, cells_series: np.ndarray,
                 cell_cutoff_v: np.ndarray) -> np.ndarray:
    """Whether each pack must stop: terminal voltage below the cut-off per cell, or empty. (M,) bool."""
    return (terminal_v < cells_series * cell_cutoff_v) | (soc_frac <= 0.0)


def soh_frac(equivalent_full_cycles: np.ndarray, cycle_life: np.ndarray,
             eol_capacity_frac: np.ndarray) -> np.ndarray:
    """Capacity left as a fraction of new [0, 1]: linear from 1 to ``eol_capacity_frac`` at ``cycle_life``."""
    return np.clip(1.0 - (1.0 - eol_capacity_frac) * equivalent_full_cycles / cycle_life, 0.0, 1.0)


def full_cycles_of(current_a: np.ndarray, dt_s: float, capacity_ah: np.ndarray) -> np.ndarray:
    """Equivalent full cycles used by ``|I|`` over ``dt_s``: a full discharge plus a full recharge is one."""
    return np.abs(current_a) * dt_s / (3600.0 * 2.0 * capacity_ah)


def energy_remaining_wh(soc_frac: np.ndarray, capacity_eff_ah: np.ndarray, cells_series: np.ndarray) -> np.ndarray:
    """Open-circuit energy left down to SOC 0 [Wh], ``cells Q int_0^SOC OCV``; an upper bound (no R losses)."""
    return cells_series * capacity_eff_ah * _cell_ocv_integral_v(soc_frac)
