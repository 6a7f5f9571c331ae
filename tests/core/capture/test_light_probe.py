"""Light direction from a mirror sphere (core.capture.light_probe): synthetic renders
with a known distant light (probe_images.py, shared with test_sphere_outline.py)."""

import numpy as np
import pytest
from probe_images import (
    BALL,
    BALL_LIGHT,
    CAM,
    CAM_SMALL,
    PERSP_LIGHTS,
    SPHERE_CENTRES,
    TOL_DEG,
    outline_circle,
    render_orthographic,
    render_perspective,
    render_probe_photo,
)
from probe_images import angle_deg as _angle_deg
from probe_images import frame_with_z as _frame_with_z
from probe_images import grazing as _grazing
from probe_images import unit as _unit

from brdf_reconstruct.core.capture import light_probe as lp

CENTER, RADIUS = (220.3, 226.6), 200.0
ORTHO_LIGHTS = {
    "at_camera": [0.0, 0.0, 1.0],
    "upper_right": [0.5, 0.3, 0.8],
    "lower_left": [-0.6, -0.2, 0.5],
    "side": [0.9, 0.1, 0.1],
    "near_grazing_140deg": _grazing(140.0, 35.0),
}


@pytest.mark.parametrize("name", ORTHO_LIGHTS)
def test_orthographic_recovers_light(name):
    l_true = _unit(ORTHO_LIGHTS[name])
    res = lp.light_from_sphere(render_orthographic(l_true), CENTER, RADIUS)
    assert _angle_deg(res.direction, l_true) < TOL_DEG
    assert np.isclose(np.linalg.norm(res.direction), 1.0)
    assert res.direction_world is None
    assert 0.0 < res.uncertainty_rad < np.radians(5.0)


def test_light_at_camera_puts_highlight_at_centre():
    res = lp.light_from_sphere(render_orthographic([0, 0, 1]), CENTER, RADIUS)
    assert np.allclose(res.highlight_px, CENTER, atol=0.05)
    assert np.allclose(res.direction, [0, 0, 1], atol=1e-3)
    assert np.allclose(res.normal, res.direction, atol=1e-3)  # the one case n == l


def test_naive_normal_answer_is_wrong_off_axis():
    # METHOD §7 pitfall: returning n is off by half the light's angle from the view.
    l_true = _unit([0.5, 0.3, 0.8])
    theta = _angle_deg(l_true, [0, 0, 1])
    res = lp.light_from_sphere(render_orthographic(l_true), CENTER, RADIUS)
    assert _angle_deg(res.direction, l_true) < TOL_DEG
    assert _angle_deg(res.normal, l_true) == pytest.approx(theta / 2, abs=TOL_DEG)
    assert _angle_deg(res.normal, l_true) > 10 * TOL_DEG
    assert _angle_deg(res.direction, res.normal) == pytest.approx(theta / 2, abs=TOL_DEG)


def test_orthographic_geometry_exact():
    # Highlight half-way out along +x: n = (0.5, 0, sqrt(0.75)), l = 2 nz n - v.
    l, n = lp.light_from_highlight((150.0, 100.0), (100.0, 100.0), 100.0)
    nz = np.sqrt(0.75)
    assert np.allclose(n, [0.5, 0.0, nz])
    assert np.allclose(l, [2 * nz * 0.5, 0.0, 2 * nz * nz - 1.0])
    # Image rows grow downwards, camera +y is up.
    l_up, _ = lp.light_from_highlight((100.0, 50.0), (100.0, 100.0), 100.0, camera="orthographic")
    assert l_up[1] > 0


def test_rgb_and_float32_input():
    l_true = _unit([-0.3, 0.4, 0.7])
    grey = render_orthographic(l_true)
    rgb = np.stack([grey, 0.9 * grey, 0.7 * grey], axis=-1).astype(np.float32)
    res = lp.light_from_sphere(rgb, CENTER, RADIUS)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


def test_saturated_core_and_hot_pixel():
    # A clipped highlight (flat core) plus a clipped hot pixel elsewhere on the sphere.
    l_true = _unit([0.4, -0.5, 0.75])
    img = np.minimum(render_orthographic(l_true, gain=30.0), 1.0)
    img[150, 300] = 1.0
    res = lp.light_from_sphere(img, CENTER, RADIUS)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


def test_background_outside_disc_is_ignored():
    l_true = _unit([0.2, 0.2, 0.9])
    img = render_orthographic(l_true)
    img[5:15, 5:15] = 50.0  # a bright lamp in the background, outside the disc
    res = lp.light_from_sphere(img, CENTER, RADIUS)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


@pytest.mark.parametrize("light", PERSP_LIGHTS)
@pytest.mark.parametrize("where", SPHERE_CENTRES)
def test_perspective_recovers_light(where, light):
    centre = np.array(SPHERE_CENTRES[where])
    # Lights are given relative to the view from the sphere to the camera.
    to_cam = -centre / np.linalg.norm(centre)
    rot = _frame_with_z(to_cam)
    l_true = rot @ _unit(PERSP_LIGHTS[light])
    img, _ = render_perspective(l_true, centre, CAM)
    c, r = outline_circle(centre, CAM)
    res = lp.light_from_sphere(img, c, r, camera=CAM)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


@pytest.mark.parametrize("where", SPHERE_CENTRES)
def test_perspective_light_at_camera(where):
    centre = np.array(SPHERE_CENTRES[where])
    l_true = -centre / np.linalg.norm(centre)
    img, _ = render_perspective(l_true, centre, CAM)
    c, r = outline_circle(centre, CAM)
    res = lp.light_from_sphere(img, c, r, camera=CAM)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


def test_perspective_differs_from_orthographic_off_axis():
    # Treating an off-axis perspective view as orthographic ignores that v is not +z.
    centre = np.array(SPHERE_CENTRES["off_axis"])
    l_true = _frame_with_z(-_unit(centre)) @ _unit([0.3, 0.5, 0.7])
    img, _ = render_perspective(l_true, centre, CAM)
    c, r = outline_circle(centre, CAM)
    ortho = lp.light_from_sphere(img, c, r)
    assert _angle_deg(ortho.direction, l_true) > 5.0


def test_world_space_rotation():
    l_true = _unit([0.5, 0.3, 0.8])
    angle = np.radians(30.0)
    rot = np.array(  # 30 degrees about world x, then the camera's -z looks slightly down
        [[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]]
    )
    res = lp.light_from_sphere(render_orthographic(l_true), CENTER, RADIUS, camera_to_world=rot)
    assert np.allclose(res.direction_world, rot @ res.direction)
    assert _angle_deg(res.direction_world, rot @ l_true) < TOL_DEG


def test_error_no_highlight():
    with pytest.raises(ValueError, match="black"):
        lp.light_from_sphere(np.zeros((100, 100)), (50, 50), 40)
    with pytest.raises(ValueError, match="uniform"):
        lp.light_from_sphere(np.ones((100, 100)), (50, 50), 40)


def test_error_highlight_outside_disc():
    with pytest.raises(ValueError, match="outside the sphere's disc"):
        lp.light_from_highlight((200.0, 100.0), (100.0, 100.0), 50.0)
    with pytest.raises(ValueError, match="outside the sphere's disc"):
        lp.light_from_highlight((10.0, 10.0), (319.5, 239.5), 40.0, camera=CAM)


def test_error_circle_off_image():
    with pytest.raises(ValueError, match="covers no pixel"):
        lp.light_from_sphere(np.ones((50, 50)), (500.0, 500.0), 10.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"radius_px": -3.0}, "radius_px"),
        ({"radius_px": float("nan")}, "radius_px"),
        ({"center_px": (1.0, 2.0, 3.0)}, "center_px"),
        ({"camera": "fisheye"}, "camera"),
        ({"camera": lp.PerspectiveCamera(0.0, (1.0, 1.0))}, "focal_px"),
        ({"camera_to_world": np.diag([2.0, 2.0, 2.0])}, "rotation"),
        ({"image": np.zeros((10, 10, 2))}, "image"),
        ({"circle_sigma_px": -1}, "circle_sigma_px"),
    ],
)
def test_error_bad_arguments(kwargs, match):
    args = {
        "image": render_orthographic([0, 0, 1], shape=(64, 64), center=(32, 32), radius=20),
        "center_px": (32.0, 32.0),
        "radius_px": 20.0,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        lp.light_from_sphere(**args)


def test_error_nan_in_disc():
    img = render_orthographic([0, 0, 1], shape=(64, 64), center=(32, 32), radius=20)
    img[32, 30] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        lp.light_from_sphere(img, (32.0, 32.0), 20.0)


# --- the highlight: sub-pixel, hot pixels; the uncertainty ------------------------

def _point_highlight(shape, at, peak, sigma=0.7, floor=0.05):
    """A point light's reflection spread by a Gaussian pixel filter (sigma px)."""
    rows, cols = np.indices(shape, dtype=np.float64)
    r2 = (cols - at[0]) ** 2 + (rows - at[1]) ** 2
    return floor + peak * np.exp(-r2 / (2 * sigma**2))


@pytest.mark.parametrize("at", [(50.3, 40.7), (50.1, 40.9), (50.45, 40.2)])
def test_sub_pixel_highlight_is_not_quantised(at):
    # Only the peak pixel or two reach half the peak: a centroid of those alone
    # was off by 0.1 to 0.3 px (about 0.5 degree on a 70 px sphere).
    img = _point_highlight((100, 100), at, 1000.0)
    (hx, hy), _ = lp.find_highlight(img, (50.0, 50.0), 45.0)
    assert abs(hx - at[0]) < 0.01 and abs(hy - at[1]) < 0.01


def test_hot_pixel_brighter_than_the_highlight_is_ignored():
    at = (60.4, 35.2)
    img = _point_highlight((100, 100), at, 100.0)
    img[70, 30] = 1e4  # a hot pixel on the sphere, 100 x the highlight
    (hx, hy), _ = lp.find_highlight(img, (50.0, 50.0), 45.0)
    assert abs(hx - at[0]) < 0.05 and abs(hy - at[1]) < 0.05


def test_uncertainty_grows_with_the_circle_error_and_bounds_it():
    img = render_probe_photo("black", BALL_LIGHT)
    c, r = outline_circle(BALL, CAM_SMALL)
    uncs = [lp.light_from_sphere(img, c, r, camera=CAM_SMALL, circle_sigma_px=s).uncertainty_rad
            for s in (0.0, 0.25, 2.0)]
    assert 0.0 < uncs[0] < uncs[1] < uncs[2]
    # a circle 2 px off (centre and radius): the error it causes is within its uncertainty
    off = lp.light_from_sphere(img, (c[0] + 2.0, c[1]), r + 2.0, camera=CAM_SMALL)
    assert _angle_deg(off.direction, BALL_LIGHT) < np.degrees(uncs[2])
