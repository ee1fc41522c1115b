"""WGS84 geodetic <-> ECEF <-> ENU conversions in unetyemu_ecs.geodesy.

The independent reference is GeographicLib's geodesic solver (C. F. F. Karney, "Algorithms for
geodesics", J. Geodesy 87, 2013; package ``geographiclib``, a test-only dependency), which is
accurate to ~15 nm on WGS84.

Tolerances, physically:
- ``ATOL_ROUND_TRIP_M = 1e-6`` (1 µm): float64 carries ~16 digits, so a coordinate near the Earth's
  radius (6.4e6 m) is rounded to ~1e-9 m; 1 µm is ~1000x that and 1000x below the 1 mm accuracy
  the module promises, and far below any GNSS receiver's resolution.
- ``ATOL_REFERENCE_M = 1e-3`` (1 mm): comparisons against geodesic references include the small,
  known geometric gap between a straight tangent-plane displacement and the surface arc under it
  (d³/3R² ≈ 8 µm at 1 km) plus ellipsoid-vs-sphere curvature terms of the same order; 1 mm bounds
  these with margin and is 100x tighter than the 0.1 m accuracy a simulated GPS needs.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from geographiclib.geodesic import Geodesic  # test extra: declared, so a missing one fails loudly

from unetyemu_ecs import geodesy as G

WGS84_GEODESIC = Geodesic.WGS84

ATOL_ROUND_TRIP_M = 1e-6
ATOL_REFERENCE_M = 1e-3
N_RANDOM = 2000

# Defining WGS84 values, typed in from NIMA TR8350.2 rather than imported, so a typo in the module
# is caught.
A_M = 6378137.0
F = 1.0 / 298.257223563
B_M = A_M * (1.0 - F)
E2 = F * (2.0 - F)
# Upper bound on metres per radian of latitude (meridian radius at the poles is 6.40e6 m).
M_PER_RAD_MAX = 6.4e6

ORIGINS = {
    "equator_prime_meridian": G.GeodeticOrigin(0.0, 0.0, 0.0),
    "mid_latitude_munich": G.GeodeticOrigin(48.137, 11.575, 0.0),
    "high_latitude_70n": G.GeodeticOrigin(70.0, 23.0, 0.0),
    "southern_western": G.GeodeticOrigin(-34.6, -58.4, 0.0),
    "antimeridian": G.GeodeticOrigin(-17.7, 179.99, 0.0),
}


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def meridian_radius_m(lat_deg: float) -> float:
    """Meridian radius of curvature M = a(1-e²)/(1-e² sin² lat)^1.5 (textbook, not the module)."""
    s = np.sin(np.radians(lat_deg))
    return A_M * (1.0 - E2) / (1.0 - E2 * s * s) ** 1.5


def random_enu_within_50km(rng: np.random.Generator, n: int) -> np.ndarray:
    """ENU points up to 50 km horizontally from the origin, -100 .. 5000 m up (a city fleet)."""
    r_m = 50_000.0 * np.sqrt(rng.uniform(0.0, 1.0, n))
    azimuth_rad = rng.uniform(-np.pi, np.pi, n)
    up_m = rng.uniform(-100.0, 5000.0, n)
    return np.stack([r_m * np.cos(azimuth_rad), r_m * np.sin(azimuth_rad), up_m], axis=-1)


# ---------------------------------------------------------------------------------------------
# Geodetic <-> ECEF
# ---------------------------------------------------------------------------------------------

def test_equator_prime_meridian_lies_on_ecef_x_at_semi_major_axis():
    # GIVEN lat 0, lon 0, height 0  WHEN converted to ECEF  THEN it is (a, 0, 0)
    assert_allclose(G.geodetic_to_ecef(0.0, 0.0, 0.0), [A_M, 0.0, 0.0], atol=ATOL_ROUND_TRIP_M)


def test_north_pole_lies_on_ecef_z_at_semi_minor_axis():
    # GIVEN the north pole at height 0  WHEN converted to ECEF  THEN it is (0, 0, b)
    assert_allclose(G.geodetic_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, B_M], atol=ATOL_ROUND_TRIP_M)


def test_module_constants_are_the_wgs84_defining_values():
    # GIVEN the module's ellipsoid  THEN it is WGS84 (TR8350.2 table 3.1)
    assert G.WGS84_A_M == A_M
    assert G.WGS84_F == pytest.approx(F, rel=1e-15)
    assert G.WGS84_E2 == pytest.approx(E2, rel=1e-15)


def test_ecef_geodetic_round_trip_is_identity(rng):
    # GIVEN random ECEF points from -1 km to 100 km above the ellipsoid, all latitudes
    lat = rng.uniform(-90.0, 90.0, N_RANDOM)
    lon = rng.uniform(-180.0, 180.0, N_RANDOM)
    alt = rng.uniform(-1000.0, 100_000.0, N_RANDOM)
    pos_ecef_m = G.geodetic_to_ecef(lat, lon, alt)
    # WHEN converted to geodetic and back
    back_ecef_m = G.geodetic_to_ecef(*G.ecef_to_geodetic(pos_ecef_m))
    # THEN every point returns to within 1 µm
    assert back_ecef_m.shape == (N_RANDOM, 3)
    assert_allclose(back_ecef_m, pos_ecef_m, atol=ATOL_ROUND_TRIP_M)


def test_geodetic_ecef_round_trip_recovers_latitude_and_height(rng):
    # GIVEN random geodetic points from -1 km to 100 km, all latitudes
    lat = rng.uniform(-90.0, 90.0, N_RANDOM)
    lon = rng.uniform(-180.0, 180.0, N_RANDOM)
    alt = rng.uniform(-1000.0, 100_000.0, N_RANDOM)
    # WHEN converted to ECEF and back
    lat2, lon2, alt2 = G.ecef_to_geodetic(G.geodetic_to_ecef(lat, lon, alt))
    # THEN height and latitude (as metres along the meridian) are back within 1 µm, and the
    # longitude (as metres along the parallel, which shrinks to 0 at the poles) too
    assert_allclose(alt2, alt, atol=ATOL_ROUND_TRIP_M)
    assert_allclose(np.radians(lat2 - lat) * M_PER_RAD_MAX, 0.0, atol=ATOL_ROUND_TRIP_M)
    dlon_rad = np.radians((lon2 - lon + 180.0) % 360.0 - 180.0)
    assert_allclose(dlon_rad * A_M * np.cos(np.radians(lat)), 0.0, atol=ATOL_ROUND_TRIP_M)


def test_ecef_to_geodetic_height_is_distance_along_the_normal(rng):
    # GIVEN surface points and heights, with the point placed by hand h metres along the
    # ellipsoid normal (up = (cos lat cos lon, cos lat sin lon, sin lat))
    lat = rng.uniform(-89.9, 89.9, N_RANDOM)
    lon = rng.uniform(-180.0, 180.0, N_RANDOM)
    alt = rng.uniform(-1000.0, 100_000.0, N_RANDOM)
    la, lo = np.radians(lat), np.radians(lon)
    n_m = A_M / np.sqrt(1.0 - E2 * np.sin(la) ** 2)
    foot = np.stack([n_m * np.cos(la) * np.cos(lo), n_m * np.cos(la) * np.sin(lo),
                     n_m * (1.0 - E2) * np.sin(la)], axis=-1)
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
    # WHEN the point is converted to geodetic
    lat2, _, alt2 = G.ecef_to_geodetic(foot + alt[:, None] * up)
    # THEN the height and latitude are the ones used to place it
    assert_allclose(alt2, alt, atol=ATOL_ROUND_TRIP_M)
    assert_allclose(np.radians(lat2 - lat) * M_PER_RAD_MAX, 0.0, atol=ATOL_ROUND_TRIP_M)


# ---------------------------------------------------------------------------------------------
# ENU <-> geodetic
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("origin", ORIGINS.values(), ids=ORIGINS.keys())
def test_enu_geodetic_round_trip_is_identity_within_50km(rng, origin):
    # GIVEN random ENU points within 50 km and -100 .. 5000 m of the origin
    pos_enu_m = random_enu_within_50km(rng, N_RANDOM)
    # WHEN converted to geodetic and back
    back_enu_m = G.geodetic_to_enu(*G.enu_to_geodetic(pos_enu_m, origin), origin)
    # THEN each point is back within 1 µm
    assert back_enu_m.shape == (N_RANDOM, 3)
    assert_allclose(back_enu_m, pos_enu_m, atol=ATOL_ROUND_TRIP_M)


@pytest.mark.parametrize("origin", ORIGINS.values(), ids=ORIGINS.keys())
def test_point_1km_north_maps_to_geodesic_reference_latitude(origin):
    # GIVEN ENU (0, 1000, 0): 1000 m along the tangent plane's north axis
    # WHEN converted to geodetic
    lat, lon, _ = G.enu_to_geodetic([0.0, 1000.0, 0.0], origin)
    # THEN the latitude equals GeographicLib's point 1000 m due north along the surface (the
    # tangent length and the arc under it differ by d³/3M² ≈ 8 µm), within 1 mm along the meridian,
    # and the longitude is unchanged (the point stays in the origin's meridian plane)
    ref = WGS84_GEODESIC.Direct(origin.lat_deg, origin.lon_deg, 0.0, 1000.0)
    assert abs(np.radians(lat - ref["lat2"])) * M_PER_RAD_MAX < ATOL_REFERENCE_M
    assert abs(lon - origin.lon_deg) * 3600.0 < 1e-9  # 1e-9 arcsec ≈ 30 nm


@pytest.mark.parametrize("origin", ORIGINS.values(), ids=ORIGINS.keys())
def test_point_1km_east_is_1km_away_at_azimuth_90deg(origin):
    # GIVEN ENU (1000, 0, 0): 1000 m along the tangent plane's east axis
    # WHEN converted to geodetic
    lat, lon, _ = G.enu_to_geodetic([1000.0, 0.0, 0.0], origin)
    # THEN GeographicLib finds it 1000 m from the origin along the surface (within 1 mm), at
    # azimuth 90 deg (1e-6 deg of azimuth is 17 µm sideways at 1 km)
    inv = WGS84_GEODESIC.Inverse(origin.lat_deg, origin.lon_deg, float(lat), float(lon))
    assert abs(inv["s12"] - 1000.0) < ATOL_REFERENCE_M
    assert abs(inv["azi1"] - 90.0) < 1e-6


def test_point_1km_north_rises_about_8cm_above_the_ellipsoid():
    # GIVEN a mid-latitude origin on the ellipsoid and ENU (0, 1000, 0)
    origin = ORIGINS["mid_latitude_munich"]
    # WHEN converted to geodetic
    _, _, alt = G.enu_to_geodetic([0.0, 1000.0, 0.0], origin)
    # THEN the height is the tangent plane's rise over the osculating meridian circle,
    # sqrt(M² + d²) - M ≈ 7.86 cm (metres-as-degrees would give 0), within 1 mm
    m = meridian_radius_m(origin.lat_deg)
    assert alt == pytest.approx(np.hypot(m, 1000.0) - m, abs=ATOL_REFERENCE_M)


def test_elevated_origin_scales_surface_arc_by_radius_ratio():
    # GIVEN an origin 520 m above the ellipsoid and ENU (0, 1000, 0) at that height
    origin = G.GeodeticOrigin(48.137, 11.575, 520.0)
    # WHEN converted to geodetic
    lat, lon, _ = G.enu_to_geodetic([0.0, 1000.0, 0.0], origin)
    # THEN the surface arc beneath it is shorter by M / (M + h0) (about 8 cm): the ENU plane sits
    # at the origin's height, so 1 km there subtends a smaller angle; GeographicLib measures it
    m = meridian_radius_m(origin.lat_deg)
    expected_arc_m = m * np.arctan(1000.0 / (m + origin.alt_m))
    inv = WGS84_GEODESIC.Inverse(origin.lat_deg, origin.lon_deg, float(lat), float(lon))
    assert inv["s12"] == pytest.approx(expected_arc_m, abs=ATOL_REFERENCE_M)


def test_equator_origin_enu_axes_follow_the_equatorial_circle(rng):
    # GIVEN the equator/prime-meridian origin, where ENU = (ECEF y, ECEF z, ECEF x - a) exactly,
    # and points moved east and up (so they stay in the equatorial plane, a circle of radius a)
    origin = ORIGINS["equator_prime_meridian"]
    east_m = rng.uniform(-50_000.0, 50_000.0, N_RANDOM)
    up_m = rng.uniform(-100.0, 5000.0, N_RANDOM)
    pos_enu_m = np.stack([east_m, np.zeros(N_RANDOM), up_m], axis=-1)
    # WHEN converted to geodetic
    lat, lon, alt = G.enu_to_geodetic(pos_enu_m, origin)
    # THEN latitude stays 0, longitude is the polar angle, height is the radial excess over a
    assert_allclose(np.radians(lat) * M_PER_RAD_MAX, 0.0, atol=ATOL_ROUND_TRIP_M)
    assert_allclose(np.radians(lon), np.arctan2(east_m, A_M + up_m), atol=ATOL_ROUND_TRIP_M / A_M)
    assert_allclose(alt, np.hypot(A_M + up_m, east_m) - A_M, atol=ATOL_ROUND_TRIP_M)


def test_up_from_origin_changes_only_height():
    # GIVEN a high-latitude origin and a point 100 m straight up the ellipsoid normal
    origin = ORIGINS["high_latitude_70n"]
    # WHEN converted to geodetic
    lat, lon, alt = G.enu_to_geodetic([0.0, 0.0, 100.0], origin)
    # THEN latitude and longitude are the origin's and the height is 100 m
    assert abs(np.radians(lat - origin.lat_deg)) * M_PER_RAD_MAX < ATOL_ROUND_TRIP_M
    assert abs(lon - origin.lon_deg) * 3600.0 < 1e-9
    assert alt == pytest.approx(100.0, abs=ATOL_ROUND_TRIP_M)


def test_origin_maps_to_enu_zero():
    # GIVEN any origin  WHEN its own coordinates are converted to ENU  THEN the result is 0
    for origin in ORIGINS.values():
        pos = G.geodetic_to_enu(origin.lat_deg, origin.lon_deg, origin.alt_m, origin)
        assert_allclose(pos, np.zeros(3), atol=ATOL_ROUND_TRIP_M)


# ---------------------------------------------------------------------------------------------
# LocalTangentPlane, shapes and validation
# ---------------------------------------------------------------------------------------------

def test_tangent_plane_rotation_is_proper_and_up_is_the_ellipsoid_normal():
    # GIVEN a tangent plane at 70 N
    plane = G.LocalTangentPlane(ORIGINS["high_latitude_70n"])
    R = plane.R_ecef_enu
    # THEN R_ecef_enu is orthonormal with det +1, and its up column is the geodetic normal
    assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
    la, lo = np.radians(70.0), np.radians(23.0)
    assert_allclose(R[:, 2], [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)],
                    atol=1e-14)


def test_tangent_plane_methods_equal_module_functions(rng):
    # GIVEN a precomputed plane and the module-level functions on the same origin
    origin = ORIGINS["southern_western"]
    plane = G.LocalTangentPlane(origin)
    pos_enu_m = random_enu_within_50km(rng, 50)
    # WHEN both convert the same points  THEN the results are identical
    for a, b in zip(plane.to_geodetic(pos_enu_m), G.enu_to_geodetic(pos_enu_m, origin)):
        assert np.array_equal(a, b)
    lat, lon, alt = plane.to_geodetic(pos_enu_m)
    assert np.array_equal(plane.to_enu(lat, lon, alt), G.geodetic_to_enu(lat, lon, alt, origin))


def test_single_point_gives_scalars_and_fleet_gives_arrays(rng):
    # GIVEN one (3,) point, a (1, 3) fleet and a (7, 3) fleet
    origin = ORIGINS["mid_latitude_munich"]
    single = G.enu_to_geodetic([10.0, 20.0, 30.0], origin)
    one = G.enu_to_geodetic(np.array([[10.0, 20.0, 30.0]]), origin)
    many = G.enu_to_geodetic(random_enu_within_50km(rng, 7), origin)
    # THEN shapes follow the leading dimensions, and N = 1 matches the single point
    assert all(np.shape(x) == () for x in single)
    assert all(np.shape(x) == (1,) for x in one)
    assert all(np.shape(x) == (7,) for x in many)
    assert_allclose(np.array(one)[:, 0], np.array(single), atol=0.0)
    assert G.geodetic_to_enu(*single, origin).shape == (3,)
    assert G.geodetic_to_enu(*many, origin).shape == (7, 3)


def test_geodetic_origin_rejects_latitude_beyond_pole():
    # GIVEN a latitude of 91 deg  WHEN an origin is built  THEN it is refused
    with pytest.raises(ValueError):
        G.GeodeticOrigin(91.0, 0.0, 0.0)
