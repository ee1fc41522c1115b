"""The RGB camera's compiled shading gives, pixel for pixel, the colours of the array formula it replaced."""

import numpy as np

from unetyemu_ecs.sensors.camera import AMBIENT, SKY_RGB, SUN_DIR_ENU, _CLASS_RGB, shade_pixels
from unetyemu_ecs.sensors.raycast import MOVING_BODY, NO_HIT


def numpy_shading(cls, box, normal, dirs_w, t, max_range_m, body_rgb):
    rgb = _CLASS_RGB[np.clip(cls, 0, 255)]
    body = cls == MOVING_BODY
    rgb[body] = body_rgb[box[body]]
    normal = np.where((np.einsum("ij,ij->i", normal, dirs_w) > 0)[:, None], -normal, normal)   # face the camera
    rgb = rgb * (AMBIENT + (1.0 - AMBIENT) * np.clip(normal @ SUN_DIR_ENU, 0.0, 1.0))[:, None]
    rgb[(cls == NO_HIT) | ~(t <= max_range_m)] = SKY_RGB
    return np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8)


def test_shading_of_classes_bodies_back_faces_and_sky_is_the_array_formulas():
    rng = np.random.default_rng(3)
    m = 20_000
    cls = rng.choice(np.array([NO_HIT, 0, 1, 2, 3, 4, 5, 6, MOVING_BODY], dtype=np.int16), m)
    box = np.where(cls == MOVING_BODY, rng.integers(0, 4, m), -1).astype(np.int32)
    normal = rng.normal(size=(m, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    dirs_w = rng.normal(size=(m, 3)).astype(np.float32)
    dirs_w /= np.linalg.norm(dirs_w, axis=1, keepdims=True)
    t = rng.uniform(0.1, 150.0, m).astype(np.float32)
    t[::97] = np.inf
    t[::89] = np.nan
    body_rgb = rng.uniform(0.0, 1.0, (4, 3))
    pixels = np.empty((m, 3), dtype=np.uint8)
    shade_pixels(cls, box, normal, dirs_w, t, 100.0, _CLASS_RGB, body_rgb, pixels)
    np.testing.assert_array_equal(pixels, numpy_shading(cls, box, normal, dirs_w, t, 100.0, body_rgb))
    sky = (cls == NO_HIT) | ~(t <= 100.0)
    assert sky.any() and (pixels[sky] == np.round(SKY_RGB * 255.0)).all()
    lit_from_above = np.array([[0.0, 0.0, 1.0]], dtype=np.float32)       # a road seen from above: sun-lit
    one = np.empty((1, 3), dtype=np.uint8)
    shade_pixels(np.array([2], dtype=np.int16), np.array([-1], dtype=np.int32), lit_from_above,
                 np.array([[0.0, 0.0, -1.0]], dtype=np.float32), np.array([5.0], dtype=np.float32), 100.0,
                 _CLASS_RGB, body_rgb, one)
    expected = _CLASS_RGB[2] * (AMBIENT + (1.0 - AMBIENT) * SUN_DIR_ENU[2]) * 255.0 + 0.5
    np.testing.assert_array_equal(one[0], expected.astype(np.uint8))
