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
    point, ``last_seg`` (M,) its last valid segment, ``base`` (M,) the flat row of its segment 0. Every
    value is computed with the operations :func:`pure_pursuit` uses, row by row (bit for bit the same).
    """

    __slots__ = ("width", "rows", "base", "cum", "total", "last", "last_seg", "vec", "length2", "seg_len",
                 "cum_start", "len_u", "ok_t", "ok_u", "all_ok", "first", "ad")

    def __init__(self, route_enu_m: np.ndarray, n_points: np.ndarray, speeds_m_s: np.ndarray) -> None:
        m, w = route_enu_m.shape[0], route_enu_m.shape[1]
        k = m * (w - 1)
        self.width = w
        self.rows = np.arange(m)
        self.base = self.rows * (w - 1)
        self.cum, self.total, self.last = np.zeros((m, w)), np.zeros(m), np.zeros((m, 3))
        self.last_seg = np.zeros(m, dtype=np.result_type(n_points, 2))
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
        # every segment long enough for both divisions (then no row needs their masked form)
        self.all_ok = (np.count_nonzero(self.ok_t) == self.ok_t.size, np.count_nonzero(self.ok_u) == self.ok_u.size)
        if w == 2:       # one segment per route: its columns as contiguous arrays, no gather needed
            self.first = (self.vec[:, 0:3].copy(), self.vec[:, 3:6].copy(), self.vec[:, 6:9].copy(),
                          self.vec[:, 9:12].copy())
        else:            # what the segment search gathers: start point and difference
            self.ad = self.vec[:, 0:6].copy()


def _divide_or_one(num: np.ndarray, den: np.ndarray, ok: np.ndarray, all_ok: bool) -> np.ndarray:
    """``num / den`` where ``ok`` (den > 1e-12), 1 elsewhere (``all_ok``: ``ok`` is all True)."""
    return num / den if all_ok else np.divide(num, den, out=np.ones(den.shape[0]), where=ok)


def _project_kept(pos: np.ndarray, a: np.ndarray, d: np.ndarray, length2: np.ndarray, ok: np.ndarray, all_ok: bool
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_project` on segments a -> a + d whose ``length2`` (d.d) and ``ok`` (length2 > 1e-12) are kept;
    return (t in [0,1], the foot of the perpendicular)."""
    t = _divide_or_one(np.einsum("mi,mi->m", pos - a, d), length2, ok, all_ok)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    return t, a + t[:, None] * d


def pursue(pos_enu_m: np.ndarray, segment: np.ndarray, lead_m: np.ndarray, final_zone_min_m: np.ndarray,
           geometry: RouteGeometry, rows: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """:func:`pure_pursuit` of routes whose :class:`RouteGeometry` the caller keeps, bit for bit: the fields
    of its :class:`PursuitResult` as a tuple (target, segment, speed limits, distance to go, cross-track,
    distance to the last point).

    ``rows`` : the geometry's rows of the M drones (None: all of them, in order); ``segment`` (M,) >= 0;
    ``lead_m`` (M,); ``final_zone_min_m`` (M,) is ``np.maximum(final_zone_m, 1e-9)``.
    """
    g = geometry
    m = pos_enu_m.shape[0]
    all_ok_t, all_ok_u = g.all_ok                  # (for a subset of the rows: true if true for all)
    if g.width == 2:                               # one segment: no search, no gather for all rows
        seg = np.zeros(m, dtype=np.intp)
        if rows is None:
            (a, d, v, dv), length2, seg_len, cum_seg, len_u = g.first, g.length2, g.seg_len, g.cum_start, g.len_u
            ok_t, ok_u, total, last = g.ok_t, g.ok_u, g.total, g.last
        else:
            vec = g.vec.take(rows, axis=0)
            a, d, v, dv = vec[:, 0:3], vec[:, 3:6], vec[:, 6:9], vec[:, 9:12]
            length2, seg_len, cum_seg, len_u = g.length2[rows], g.seg_len[rows], g.cum_start[rows], g.len_u[rows]
            ok_t, ok_u, total, last = g.ok_t[rows], g.ok_u[rows], g.total[rows], g.last[rows]
        t, foot = _project_kept(pos_enu_m, a, d, length2, ok_t, all_ok_t)
        s_proj = cum_seg + t * seg_len
        remaining = np.maximum(total - s_proj, 0.0)
        lead = lead_m * np.minimum(remaining / final_zone_min_m, 1.0)             # remaining >= 0
        s_target = np.minimum(s_proj + lead, total)
        # the target's segment is segment 0, whose cumulative start is +0.0: s_target - 0.0 == s_target
        u = _divide_or_one(s_target, len_u, ok_u, all_ok_u)
        a_j, d_j = a, d
    else:
        base = g.base if rows is None else g.base[rows]
        last_seg = g.last_seg if rows is None else g.last_seg[rows]
        seg = np.minimum(segment.astype(np.intp), last_seg)
        # Advance while the drone has passed the end of its segment, or is nearer to the next one
        # (both segments projected in one batch of 2M rows: the current ones, then the next ones).
        pos2 = None
        for _ in range(g.width):
            can = seg < last_seg
            if not np.count_nonzero(can):
                break
            if pos2 is None:
                pos2 = np.concatenate((pos_enu_m, pos_enu_m))
                base2 = np.concatenate((base, base))
            # the next segment of a drone on its route's last is its own (then ``can`` is False)
            flat2 = base2 + np.concatenate((seg, np.minimum(seg + 1, g.width - 2)))
            ad2 = g.ad.take(flat2, axis=0)
            t2, foot2 = _project_kept(pos2, ad2[:, 0:3], ad2[:, 3:6], g.length2.take(flat2), g.ok_t.take(flat2),
                                      all_ok_t)
            dist2 = row_norm(pos2 - foot2)
            step = can & ((t2[:m] >= 1.0) | ((dist2[m:] <= dist2[:m]) & (t2[m:] > 0.0)))
            if not np.count_nonzero(step):
                break
            seg = seg + step
        flat = base + seg
        vec = g.vec.take(flat, axis=0)
        a, d, v, dv = vec[:, 0:3], vec[:, 3:6], vec[:, 6:9], vec[:, 9:12]
        total, last = (g.total, g.last) if rows is None else (g.total[rows], g.last[rows])
        t, foot = _project_kept(pos_enu_m, a, d, g.length2.take(flat), g.ok_t.take(flat), all_ok_t)
        s_proj = g.cum_start.take(flat) + t * g.seg_len.take(flat)
        remaining = np.maximum(total - s_proj, 0.0)
        lead = lead_m * np.minimum(remaining / final_zone_min_m, 1.0)             # remaining >= 0
        s_target = np.minimum(s_proj + lead, total)
        # Segment holding s_target: last j with cum[j] <= s_target, limited to valid segments.
        cum = g.cum if rows is None else g.cum[rows]
        j = np.count_nonzero(cum <= s_target[:, None] + 1e-12, axis=1) - 1
        flat_j = base + np.minimum(np.maximum(j, 0), last_seg)
        vec_j = g.vec.take(flat_j, axis=0)
        u = _divide_or_one(s_target - g.cum_start.take(flat_j), g.len_u.take(flat_j), g.ok_u.take(flat_j), all_ok_u)
        a_j, d_j = vec_j[:, 0:3], vec_j[:, 3:6]
    u = np.minimum(np.maximum(u, 0.0), 1.0)
    # the drone's distance to its segment and to the last point: one norm of 2M rows
    dist = row_norm(np.concatenate((pos_enu_m - foot, last - pos_enu_m)))
    cross = dist[:m]
    return a_j + u[:, None] * d_j, seg, v + t[:, None] * dv, remaining + cross, cross, dist[m:]
