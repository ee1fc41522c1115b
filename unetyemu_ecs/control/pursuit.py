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

from .compiled import jit


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


def route_lengths(route_enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment lengths (M, W-1) and cumulative length at each point (M, W) [m] of padded routes (M, W, 3)."""
    seg_lengths = np.linalg.norm(np.diff(route_enu_m, axis=1), axis=2)
    return seg_lengths, np.concatenate([np.zeros((route_enu_m.shape[0], 1)), np.cumsum(seg_lengths, axis=1)], axis=1)


def pure_pursuit(pos_enu_m: np.ndarray, route_enu_m: np.ndarray, n_points: np.ndarray, segment: np.ndarray,
                 speeds_m_s: np.ndarray, lead_m: np.ndarray, final_zone_m: np.ndarray) -> PursuitResult:
    """Advance each drone along its route and place its virtual target.

    Parameters
    ----------
    pos_enu_m : (M, 3) [m], ENU, drone positions
    route_enu_m : (M, W, 3) [m], ENU, route points (point 0 is where the route started), W >= 2
    n_points : (M,) int, number of valid points per route (>= 2)
    segment : (M,) int >= 0, active segment from the previous step (0 at the start)
    speeds_m_s : (M, W, 3) [m/s], (cruise, climb, descent) speed at each route point
    lead_m : (M,) [m], lead distance of the virtual target
    final_zone_m : (M,) [m], length of the final approach in which the lead shrinks to zero

    It is :func:`pursue` on the routes' :class:`RouteGeometry`, made here; a caller that keeps its routes
    between steps keeps their geometry instead and calls :func:`pursue` (the route-following system).
    """
    geometry = RouteGeometry(route_enu_m, n_points, speeds_m_s)
    return PursuitResult(*pursue(pos_enu_m, segment, lead_m, np.maximum(final_zone_m, 1e-9), geometry))


# -- routes kept between steps -----------------------------------------------------------------------------------------
class RouteGeometry:
    """What :func:`pursue` needs of M padded routes (M, W, 3) that changes only with the routes.

    A caller that keeps its routes between steps (the route-following system) keeps this with them and
    updates (:meth:`update`) the rows whose routes changed, so that a step only projects the drones. Per segment
    (row ``m * (W-1) + k`` for segment ``k``: route[m, k] -> route[m, k+1]), flat over the M routes:

    - ``vec`` (M (W-1), 12): start point, ``route[k+1] - route[k]``, speeds at the start, speed change;
    - ``length2``, ``seg_len``, ``cum_start``, ``len_u`` (M (W-1),): squared length (the dot product of the
      difference), its square root, cumulative length at the start, :func:`route_lengths` length;
    - ``ok_t``, ``ok_u`` (M (W-1),) bool: ``length2 > 1e-12``, ``len_u > 1e-12``;

    per route ``cum`` (M, W), ``total`` (M,) length to the last valid point, ``last`` (M, 3) last valid
    point, ``last_seg`` (M,) its last valid segment. Every
    value is computed with the operations :func:`pure_pursuit` uses, row by row (bit for bit the same).
    """

    __slots__ = ("width", "rows", "cum", "total", "last", "last_seg", "vec", "length2", "seg_len",
                 "cum_start", "len_u", "ok_t", "ok_u")

    def __init__(self, route_enu_m: np.ndarray, n_points: np.ndarray, speeds_m_s: np.ndarray) -> None:
        m, w = route_enu_m.shape[0], route_enu_m.shape[1]
        k = m * (w - 1)
        self.width = w
        self.rows = np.arange(m)
        self.cum, self.total, self.last = np.zeros((m, w)), np.zeros(m), np.zeros((m, 3))
        self.last_seg = np.zeros(m, dtype=np.intp)
        self.vec = np.zeros((k, 12))
        self.length2, self.seg_len, self.cum_start, self.len_u = np.zeros(k), np.zeros(k), np.zeros(k), np.zeros(k)
        self.ok_t, self.ok_u = np.zeros(k, dtype=bool), np.zeros(k, dtype=bool)
        self.update(self.rows, route_enu_m, n_points, speeds_m_s)

    def update(self, rows: np.ndarray, route_enu_m: np.ndarray, n_points: np.ndarray, speeds_m_s: np.ndarray) -> None:
        """Compute again the rows ``rows`` (indices) of the routes (M, W, 3), ``n_points`` (M,) and speeds
        (M, W, 3) (their padded width W unchanged)."""
        m, w = self.rows.size, self.width
        route, speeds, n = route_enu_m[rows], speeds_m_s[rows], n_points[rows]
        idx = np.arange(rows.size)
        seg_lengths, cum = route_lengths(route)
        d = route[:, 1:] - route[:, :-1]
        flat = d.reshape(-1, 3)
        length2 = np.einsum("mi,mi->m", flat, flat).reshape(rows.size, w - 1)
        vec = self.vec.reshape(m, w - 1, 12)
        vec[rows, :, 0:3] = route[:, :-1]
        vec[rows, :, 3:6] = d
        vec[rows, :, 6:9] = speeds[:, :-1]
        vec[rows, :, 9:12] = speeds[:, 1:] - speeds[:, :-1]
        self.length2.reshape(m, w - 1)[rows] = length2
        self.seg_len.reshape(m, w - 1)[rows] = np.sqrt(length2)
        self.cum_start.reshape(m, w - 1)[rows] = cum[:, :-1]
        self.len_u.reshape(m, w - 1)[rows] = seg_lengths
        self.ok_t.reshape(m, w - 1)[rows] = length2 > 1e-12
        self.ok_u.reshape(m, w - 1)[rows] = seg_lengths > 1e-12
        self.cum[rows] = cum
        self.total[rows] = cum[idx, n - 1]
        self.last[rows] = route[idx, n - 1]
        self.last_seg[rows] = n - 2


def pursue(pos_enu_m: np.ndarray, segment: np.ndarray, lead_m: np.ndarray, final_zone_min_m: np.ndarray,
           geometry: RouteGeometry, rows: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """:func:`pure_pursuit` of routes whose :class:`RouteGeometry` the caller keeps, bit for bit: the fields
    of its :class:`PursuitResult` as a tuple (target, segment, speed limits, distance to go, cross-track,
    distance to the last point). Compiled, drone by drone (:func:`pursue_into`).

    ``rows`` : the geometry's rows of the M drones (None: all of them, in order); ``segment`` (M,) >= 0;
    ``lead_m`` (M,); ``final_zone_min_m`` (M,) is ``np.maximum(final_zone_m, 1e-9)``.
    """
    g = geometry
    m = pos_enu_m.shape[0]
    target, speeds = np.empty((m, 3)), np.empty((m, 3))
    seg = np.empty(m, dtype=np.intp)
    to_go, cross, to_final = np.empty(m), np.empty(m), np.empty(m)
    geo_rows = g.rows if rows is None else np.asarray(rows, dtype=np.intp)
    _pursue_rows(np.asarray(pos_enu_m, dtype=float), np.asarray(segment).astype(np.intp, copy=False),
                 np.asarray(lead_m, dtype=float), np.asarray(final_zone_min_m, dtype=float), geo_rows, g.width,
                 g.last_seg, g.vec, g.length2, g.ok_t, g.seg_len, g.cum_start, g.len_u,
                 g.ok_u, g.cum, g.total, g.last, target, seg, speeds, to_go, cross, to_final)
    return target, seg, speeds, to_go, cross, to_final


@jit
def project_on_segment(pos, vec, length2, ok):
    """Projection of ``pos`` (3,) on the segment ``a -> a + d`` of ``vec`` (a, d, ...) whose ``length2`` (d.d) and
    ``ok`` (length2 > 1e-12) are kept: t in [0, 1] (1 on a segment too short to divide by) and the distance from
    ``pos`` to the foot of the perpendicular; sums in numpy's einsum order, clamps as numpy's (signed zeros)."""
    e0, e1, e2 = pos[0] - vec[0], pos[1] - vec[1], pos[2] - vec[2]
    t = ((e0 * vec[3] + e2 * vec[5]) + e1 * vec[4]) / length2 if ok else 1.0
    t = min(1.0, max(0.0, t))
    f0, f1, f2 = pos[0] - (vec[0] + t * vec[3]), pos[1] - (vec[1] + t * vec[4]), pos[2] - (vec[2] + t * vec[5])
    return t, np.sqrt((f0 * f0 + f2 * f2) + f1 * f1)


@jit
def pursue_into(pos, segment, lead_m, final_zone_min_m, g, width, last_seg, vec, length2, ok_t, seg_len, cum_start,
                len_u, ok_u, cum, total, last, target, speeds):
    """:func:`pursue` of one drone on geometry row ``g``: writes ``target`` (3,) and ``speeds`` (3,), returns
    (segment, distance to go, cross-track, distance to the last point)."""
    base = g * (width - 1)
    seg = min(segment, last_seg[g])
    # advance while the drone has passed the end of its segment, or is nearer to the next one
    for _ in range(width):
        if not seg < last_seg[g]:
            break
        cur, nxt = base + seg, base + min(seg + 1, width - 2)
        t_cur, dist_cur = project_on_segment(pos, vec[cur], length2[cur], ok_t[cur])
        t_next, dist_next = project_on_segment(pos, vec[nxt], length2[nxt], ok_t[nxt])
        if not (t_cur >= 1.0 or (dist_next <= dist_cur and t_next > 0.0)):
            break
        seg += 1
    flat = base + seg
    v = vec[flat]
    t, cross = project_on_segment(pos, v, length2[flat], ok_t[flat])
    s_proj = cum_start[flat] + t * seg_len[flat]
    remaining = max(0.0, total[g] - s_proj)
    lead = lead_m * min(1.0, remaining / final_zone_min_m)               # remaining >= 0
    s_target = min(total[g], s_proj + lead)
    # the segment holding s_target: the last j with cum[j] <= s_target, limited to the valid segments
    j = -1
    for w in range(width):
        if cum[g, w] <= s_target + 1e-12:
            j += 1
    flat_j = base + min(last_seg[g], max(0, j))
    u = (s_target - cum_start[flat_j]) / len_u[flat_j] if ok_u[flat_j] else 1.0
    u = min(1.0, max(0.0, u))
    vj = vec[flat_j]
    for i in range(3):
        target[i] = vj[i] + u * vj[3 + i]
        speeds[i] = v[6 + i] + t * v[9 + i]
    e0, e1, e2 = last[g, 0] - pos[0], last[g, 1] - pos[1], last[g, 2] - pos[2]
    return seg, remaining + cross, cross, np.sqrt((e0 * e0 + e2 * e2) + e1 * e1)


@jit
def _pursue_rows(pos, segment, lead_m, final_zone_min_m, geo_rows, width, last_seg, vec, length2, ok_t, seg_len,
                 cum_start, len_u, ok_u, cum, total, last, target, seg, speeds, to_go, cross, to_final):
    for k in range(pos.shape[0]):
        seg[k], to_go[k], cross[k], to_final[k] = pursue_into(
            pos[k], segment[k], lead_m[k], final_zone_min_m[k], geo_rows[k], width, last_seg, vec, length2, ok_t,
            seg_len, cum_start, len_u, ok_u, cum, total, last, target[k], speeds[k])
