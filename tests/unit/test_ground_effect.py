"""Ground effect against Cheeseman & Bennett (1955): the hover law at given heights, its clamp and cut-off,
its monotonic fading with height and with forward speed; and the surface-below look-up against the
scene's own per-point one. No esper, no PyBullet."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from unetyemu_ecs.control.ground_effect import (GROUND_EFFECT_CUTOFF_RADII, GROUND_EFFECT_MIN_HEIGHT_RADII,
                                                build_surface_index, ground_effect_factor, surface_below_m,
                                                surface_index_from_shapes)
from unetyemu_ecs.scene import SceneConfig, build_layout

R_M = 0.14                         # the presets' rotor radius


def cheeseman_bennett(z_over_r, advance_ratio_sq=0.0):
    """T_IGE / T_OGE = 1 / (1 - (R / 4z)^2 / (1 + (V / v_i)^2)), written out from the paper."""
    return 1.0 / (1.0 - (1.0 / (4.0 * z_over_r)) ** 2 / (1.0 + advance_ratio_sq))


# --- 1. hover law --------------------------------------------------------------------------------

def test_factor_at_one_rotor_radius_is_16_over_15():
    # GIVEN a hovering rotor one radius above the ground THEN 1 / (1 - 1/16) = 1.0667
    assert ground_effect_factor(R_M, R_M) == pytest.approx(16.0 / 15.0, rel=1e-12)
    assert ground_effect_factor(R_M, R_M) == pytest.approx(1.0667, abs=1e-4)


def test_factor_at_two_rotor_radii_is_64_over_63():
    assert ground_effect_factor(2 * R_M, R_M) == pytest.approx(64.0 / 63.0, rel=1e-12)
    assert ground_effect_factor(2 * R_M, R_M) == pytest.approx(1.0159, abs=1e-4)


def test_factor_follows_the_formula_between_the_clamp_and_the_cut_off():
    z_over_r = np.linspace(GROUND_EFFECT_MIN_HEIGHT_RADII, GROUND_EFFECT_CUTOFF_RADII, 50, endpoint=False)
    assert_allclose(ground_effect_factor(z_over_r * R_M, R_M), cheeseman_bennett(z_over_r), rtol=1e-12)


def test_factor_is_one_far_from_the_ground_and_with_no_surface_below():
    # GIVEN rotors at and above the cut-off (4 R), 10 m up, or with nothing below (inf, NaN)
    heights_m = np.array([GROUND_EFFECT_CUTOFF_RADII * R_M, 1.0, 10.0, np.inf, np.nan])
    # THEN there is no ground effect
    assert_allclose(ground_effect_factor(heights_m, R_M), 1.0)


def test_the_cut_off_is_a_step_of_under_half_a_percent():
    # the formula just below 4 R is 1 / (1 - 1/256) = 1.0039, the law's step to 1 at the cut-off
    just_below = ground_effect_factor(GROUND_EFFECT_CUTOFF_RADII * R_M * (1 - 1e-9), R_M)
    assert just_below == pytest.approx(256.0 / 255.0, rel=1e-6)
    assert just_below - 1.0 < 0.004


def test_heights_below_half_a_radius_are_clamped_to_four_thirds():
    # GIVEN rotors at R/2, R/4 (where the formula diverges), on the surface and below it
    heights_m = np.array([0.5, 0.25, 0.1, 0.0, -0.3]) * R_M
    # THEN all read the formula at z = R/2: 1 / (1 - 1/4) = 4/3, never more
    assert_allclose(ground_effect_factor(heights_m, R_M), 4.0 / 3.0, rtol=1e-12)


def test_a_clamp_at_or_below_a_quarter_radius_is_refused():
    with pytest.raises(ValueError, match="diverges"):
        ground_effect_factor(R_M, R_M, min_height_radii=0.25)


def test_factor_falls_monotonically_with_height():
    heights_m = np.linspace(0.0, 2.0, 2001)
    factor = ground_effect_factor(heights_m, R_M)
    assert np.all(np.diff(factor) <= 0.0)
    assert factor[0] == pytest.approx(4.0 / 3.0) and factor[-1] == 1.0


def test_factor_scales_with_height_over_radius_for_mixed_rotor_sizes():
    # GIVEN (M, 4) rotors of three sizes at the same height ratios (a broadcasting check)
    radius_m = np.array([0.05, 0.14, 0.6])[:, None]
    z_over_r = np.array([0.6, 1.0, 2.0, 3.0])[None, :]
    factor = ground_effect_factor(z_over_r * radius_m, radius_m)
    assert factor.shape == (3, 4)
    assert_allclose(factor, np.broadcast_to(cheeseman_bennett(z_over_r), (3, 4)), rtol=1e-12)


# --- 2. forward flight -----------------------------------------------------------------------------

def test_forward_flight_at_the_induced_velocity_halves_the_extra_thrust_term():
    # GIVEN V = v_i: (V / v_i)^2 = 1, the image term (R / 4z)^2 is halved
    factor = ground_effect_factor(R_M, R_M, inplane_speed_m_s=5.0, induced_velocity_m_s=5.0)
    assert factor == pytest.approx(1.0 / (1.0 - (1.0 / 16.0) / 2.0), rel=1e-12)


def test_forward_flight_follows_cheeseman_bennett_and_fades_with_speed():
    v_i_m_s = 6.0
    speed_m_s = np.linspace(0.0, 30.0, 61)
    factor = ground_effect_factor(R_M, R_M, speed_m_s, v_i_m_s)
    assert_allclose(factor, cheeseman_bennett(1.0, (speed_m_s / v_i_m_s) ** 2), rtol=1e-12)
    assert np.all(np.diff(factor) < 0.0)
    assert factor[0] == pytest.approx(16.0 / 15.0) and factor[-1] - 1.0 < 0.003   # V = 5 v_i: 1/26 of it


def test_hover_with_no_induced_velocity_keeps_the_hover_form_and_motion_without_wake_has_none():
    # a rotor at rest (v_i = 0) does nothing either way; the law must stay finite: hover form at V = 0
    assert ground_effect_factor(R_M, R_M, 0.0, 0.0) == pytest.approx(16.0 / 15.0)
    assert ground_effect_factor(R_M, R_M, 3.0, 0.0) == 1.0


# --- 3. the surface below ----------------------------------------------------------------------------

def test_surface_below_is_the_highest_support_top_not_above_the_point():
    # GIVEN a ground slab (top 0), a 10 m building yawed 30 deg and a 2 m pillar (cylinder)
    boxes = np.array([[0.0, 0.0, 50.0, 50.0, 0.0, 0.0],
                      [10.0, 0.0, 4.0, 2.0, np.radians(30.0), 10.0]])
    cylinders = np.array([[-10.0, 5.0, 1.0, 2.0]])
    index = build_surface_index(boxes, cylinders)
    points = np.array([[0.0, 0.0, 0.3],      # over the ground
                       [10.0, 0.0, 10.2],    # over the roof
                       [10.0, 0.0, 5.0],     # inside the building's footprint, under its roof: the ground
                       [-10.0, 5.5, 2.1],    # over the pillar
                       [-10.0, 6.5, 2.1],    # beside it
                       [80.0, 0.0, 1.0]])    # off the ground slab: nothing below
    assert_allclose(surface_below_m(index, points), [0.0, 10.0, 0.0, 2.0, 0.0, -np.inf])


def test_surface_below_agrees_with_the_layouts_per_point_look_up_over_the_generated_city():
    # GIVEN the default generated city (roads, sidewalks, buildings with yawed roofs, tree trunks, pads)
    layout = build_layout(SceneConfig(generator="urban"), 42)
    index = surface_index_from_shapes(s for obj in layout.objects for s in obj.shapes)
    rng = np.random.default_rng(1234)
    xy = rng.uniform(layout.extent_min_m - 20.0, layout.extent_max_m + 20.0, size=(2000, 2))
    # WHEN the points are above every object (so "not above the point" changes nothing)
    points = np.column_stack([xy, np.full(len(xy), 500.0)])
    expected = [layout.surface_height_m(x, y) for x, y in xy]
    found = surface_below_m(index, points)
    # THEN the indexed, vectorised look-up gives the layout's heights (ground: 0 where covered)
    covered = np.isfinite(found)
    assert_allclose(found[covered], np.asarray(expected)[covered], atol=1e-12)
    assert_allclose(np.asarray(expected)[~covered], 0.0)      # the layout reports 0 off every support
