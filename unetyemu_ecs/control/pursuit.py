"""Pure-pursuit waypoint following with a virtual target, vectorised over a fleet.

The paper's §2.1.3 (after Kishore et al. 2022): instead of steering at each waypoint, the drone
chases a *virtual target* that slides along the planned polyline a lead distance ahead of the
drone's projection onto the route. Inside the final-approach zone the lead shrinks linearly to zero
so the target settles on the last waypoint instead of dragging the drone past it. Speeds given per
waypoint are interpolated along each segment.

Routes of different lengths share padded arrays: ``route_enu_m`` is (M, W, 3) and only the first
``n_points[m]`` rows of drone ``m`` are meaningful (padding repeats the last point).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import row_norm


@dataclass(frozen=True)
class PursuitResult:
    """Output of :func:`pure_pursuit` for M drones.

    target_enu_m : (M, 3) [m] virtual target, ENU
    segment : (M,) int, index k of the active segment (route[k] -> route[k+1])
    speed_lims_m_s : (M, 3) [m/s] interpolated (horizontal cruise, climb, descent) speeds
    dist_to_go_m : (M,) [m] along-route distance left from the drone's projection, plus its
        cross-track offset (an upper bound of the distance still to fly)
    cross_track_m : (M,) [m] distance from the drone to the active segment
    dist_to_final_m : (M,) [m] straight-line distance to the last waypoint
    """

    target_enu_m: np.ndarray
    segment: np.ndarray
    speed_lims_m_s: np.ndarray
    dist_to_go_m: np.ndarray
    cross_track_m: np.ndarray
    dist_to_final_m: np.ndarray


def _project(pos: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points (M,3) on segments a->b; return (t in [0,1], length, distance to segment)."""
    d = b - a
    length2 = np.einsum("mi,mi->m", d, d)
    t = np.divide(np.einsum("mi,mi->m", pos - a, d), length2, out=np.ones_like(length2), where=length2 > 1e-12)
    t = np.minimum(np.maximum(t, 0.0), 1.0)                   # a degenerate segment: its end (t = 1)
    return t, np.sqrt(length2), row_norm(pos - (a + t[:, None] * d))


def route_lengths(route_enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment lengths (M, W-1) and cumulative length at each point (M, W) [m] of padded routes (M, W, 3)."""
    seg_lengths = np.linalg.norm(np.diff(route_enu_m, axis=1), axis=2)
    return seg_lengths, np.concatenate([np.zeros((route_enu_m.shape[0], 1)), np.cumsum(seg_lengths, axis=1)], axis=1)


def pure_pursuit(pos_enu_m: np.ndarray, route_enu_m: np.ndarray, n_points: np.ndarray, segment: np.ndarray,
                 speeds_m_s: np.ndarray, lead_m: np.ndarray, final_zone_m: np.ndarray,
                 lengths: tuple[np.ndarray, np.ndarray] | None = None) -> PursuitResult:
    """Advance each drone along its route and place its virtual target.

    Parameters
    ----------
    pos_enu_m : (M, 3) [m], ENU, drone positions
    route_enu_m : (M, W, 3) [m], ENU, route points (point 0 is where the route started), W >= 2
    n_points : (M,) int, number of valid points per route (>= 2)
    segment : (M,) int, active segment from the previous step (0 at the start)
    speeds_m_s : (M, W, 3) [m/s], (cruise, climb, descent) speed at each route point
    lead_m : (M,) [m], lead distance of the virtual target
    final_zone_m : (M,) [m], length of the final approach in which the lead shrinks to zero
    lengths : :func:`route_lengths` of ``route_enu_m`` when the caller keeps them (they change only with
        the routes); computed here when None
    """
    m_idx = np.arange(pos_enu_m.shape[0])
    last_seg = n_points - 2
    seg = np.minimum(segment.astype(np.intp), last_seg)

    # Advance while the drone has passed the end of its segment, or is nearer to the next one.
    for _ in range(route_enu_m.shape[1]):
        can = seg < last_seg
        if not can.any():
            break
        a = route_enu_m[m_idx, seg]
        b = route_enu_m[m_idx, seg + 1]
        c = route_enu_m[m_idx, np.minimum(seg + 2, route_enu_m.shape[1] - 1)]
        t, _, dist_cur = _project(pos_enu_m, a, b)
        t_next, _, dist_next = _project(pos_enu_m, b, c)
        step = can & ((t >= 1.0) | ((dist_next <= dist_cur) & (t_next > 0.0)))
        if not step.any():
            break
        seg = seg + step

    a = route_enu_m[m_idx, seg]
    b = route_enu_m[m_idx, seg + 1]
    t, seg_len, cross = _project(pos_enu_m, a, b)

    seg_lengths, cum = lengths if lengths is not None else route_lengths(route_enu_m)   # (M, W-1), (M, W)
    total = cum[m_idx, n_points - 1]
    s_proj = cum[m_idx, seg] + t * seg_len
    remaining = np.maximum(total - s_proj, 0.0)
    lead = lead_m * np.minimum(remaining / np.maximum(final_zone_m, 1e-9), 1.0)      # remaining >= 0
    s_target = np.minimum(s_proj + lead, total)

    # Segment holding s_target: last j with cum[j] <= s_target, limited to valid segments.
    j = np.count_nonzero(cum <= s_target[:, None] + 1e-12, axis=1) - 1
    j = np.minimum(np.maximum(j, 0), last_seg)
    seg_len_j = seg_lengths[m_idx, j]
    u = np.divide(s_target - cum[m_idx, j], seg_len_j, out=np.ones_like(seg_len_j), where=seg_len_j > 1e-12)
    u = np.minimum(np.maximum(u, 0.0), 1.0)
    p_j = route_enu_m[m_idx, j]
    target = p_j + u[:, None] * (route_enu_m[m_idx, j + 1] - p_j)

    v_seg = speeds_m_s[m_idx, seg]
    speeds = v_seg + t[:, None] * (speeds_m_s[m_idx, seg + 1] - v_seg)
    dist_to_final = row_norm(route_enu_m[m_idx, n_points - 1] - pos_enu_m)
    return PursuitResult(target, seg, speeds, remaining + cross, cross, dist_to_final)
