"""The probe sphere's image circle (core.capture.sphere_outline): fitted to a mask, found in
the photo itself, a drawn circle snapped to the outline. Synthetic renders with a
known sphere and light, from probe_images.py (shared with test_light_probe.py)."""

import numpy as np
import pytest
from probe_images import (
    BALL,
    BALL_LIGHT,
    CAM,
    CAM_SMALL,
    PERSP_LIGHTS,
    SPHERE_CENTRES,
    SS,
    TOL_DEG,
    outline_circle,
    render_perspective,
    render_probe_photo,
)
from probe_images import angle_deg as _angle_deg
from probe_images import frame_with_z as _frame_with_z
from probe_images import subsamples as _subsamples
from probe_images import unit as _unit

from brdf_reconstruct.core.capture import light_probe as lp
from brdf_reconstruct.core.capture import sphere_outline as so

# --- fitted to a mask (detect_sphere) ----------------------------------------------


@pytest.mark.parametrize("light", PERSP_LIGHTS)
def test_perspective_with_fitted_circle(light):
    # End to end: the circle comes from detect_sphere (cone fit) on the rendered coverage.
    centre = np.array(SPHERE_CENTRES["off_axis"])
    l_true = _frame_with_z(-_unit(centre)) @ _unit(PERSP_LIGHTS[light])
    img, mask = render_perspective(l_true, centre, CAM)
    c, r = so.detect_sphere(mask, camera=CAM)
    c_exact, r_exact = outline_circle(centre, CAM)
    assert np.allclose(c, c_exact, atol=0.2) and r == pytest.approx(r_exact, abs=0.2)
    res = lp.light_from_sphere(img, c, r, camera=CAM)
    assert _angle_deg(res.direction, l_true) < TOL_DEG


def test_plain_circle_fit_is_worse_off_axis_near_grazing():
    # Why detect_sphere takes the camera: a Kasa circle on the elliptical outline is off.
    centre = np.array(SPHERE_CENTRES["off_axis"])
    l_true = _frame_with_z(-_unit(centre)) @ _unit(PERSP_LIGHTS["near_grazing_140deg"])
    img, mask = render_perspective(l_true, centre, CAM)
    c, r = so.detect_sphere(mask)
    res = lp.light_from_sphere(img, c, r, camera=CAM)
    assert _angle_deg(res.direction, l_true) > 1.0


def test_detect_sphere_mask_image_and_errors():
    shape, c_true, r_true = (260, 300), (150.3, 120.7), 80.4
    cover = np.zeros(shape)
    for x, y in _subsamples(shape):
        cover += (x - c_true[0]) ** 2 + (y - c_true[1]) ** 2 < r_true**2
    mask = cover / SS**2 > 0.5
    c, r = so.detect_sphere(mask)
    assert np.allclose(c, c_true, atol=0.1)
    assert r == pytest.approx(r_true, abs=0.1)
    image = np.where(mask, 0.3, 0.01)[..., None] * np.ones(3)
    c2, r2 = so.detect_sphere(image)
    assert np.allclose(c2, c) and r2 == pytest.approx(r)
    with pytest.raises(ValueError, match="boundary"):
        so.detect_sphere(np.zeros((20, 20), dtype=bool))
    with pytest.raises(ValueError, match="camera"):
        so.detect_sphere(np.eye(20, dtype=bool), camera="fisheye")


# --- found in the photo itself (locate_sphere, refine_sphere) --------------------


def _circle_error(found, truth):
    (cx, cy), r = found
    (tx, ty), tr = truth
    return np.hypot(cx - tx, cy - ty), abs(r - tr)


@pytest.mark.parametrize(
    ("kind", "background"),
    [("black", 0.4), ("chrome", 0.05)],
    ids=["black_on_grey", "chrome_on_dark"],
)
def test_locate_sphere_either_polarity(kind, background):
    img = render_probe_photo(kind, BALL_LIGHT, background=background)
    found = so.locate_sphere(img, camera=CAM_SMALL)
    dc, dr = _circle_error(found, outline_circle(BALL, CAM_SMALL))
    assert dc < 0.1 and dr < 0.1
    res = lp.light_from_sphere(img, *found, camera=CAM_SMALL)
    assert _angle_deg(res.direction, BALL_LIGHT) < TOL_DEG


def test_locate_sphere_ignores_hot_pixels_and_a_clipped_highlight():
    img = np.minimum(render_probe_photo("black", BALL_LIGHT, gain=5000.0), 1.0)
    rng = np.random.default_rng(4)
    rows, cols = rng.integers(0, 240, 12), rng.integers(0, 320, 12)
    img[rows, cols] = 1.0  # clipped hot pixels, on the wall and on the ball
    found = so.locate_sphere(img, camera=CAM_SMALL)
    dc, dr = _circle_error(found, outline_circle(BALL, CAM_SMALL))
    assert dc < 0.1 and dr < 0.1
    res = lp.light_from_sphere(img, *found, camera=CAM_SMALL)
    assert _angle_deg(res.direction, BALL_LIGHT) < TOL_DEG


def test_locate_sphere_orthographic_disc():
    shape, c_true, r_true = (200, 260), (140.4, 96.8), 61.3
    cover = np.zeros(shape)
    for x, y in _subsamples(shape):
        cover += (x - c_true[0]) ** 2 + (y - c_true[1]) ** 2 < r_true**2
    img = 0.5 - 0.45 * cover / SS**2  # a dark disc on grey, anti-aliased
    (cx, cy), r = so.locate_sphere(img)
    assert np.hypot(cx - c_true[0], cy - c_true[1]) < 0.05 and abs(r - r_true) < 0.05


def test_locate_sphere_with_a_clean_plate():
    # The wall's left half is as dark as the ball: half its outline is invisible in the
    # photo alone; the difference from the clean plate shows all of it.
    wall = np.where(np.arange(320)[None, :] < 180, 0.03, 0.4) * np.ones((240, 1))
    img = render_probe_photo("black", BALL_LIGHT, background=wall)
    found = so.locate_sphere(img, camera=CAM_SMALL, background=wall)
    dc, dr = _circle_error(found, outline_circle(BALL, CAM_SMALL))
    assert dc < 0.1 and dr < 0.1


@pytest.mark.parametrize(
    "image",
    [
        np.random.default_rng(1).normal(0.3, 0.01, (120, 160)),
        np.pad(np.full((60, 60), 0.8), 40, constant_values=0.1),  # a square is no sphere
    ],
    ids=["noise", "square"],
)
def test_locate_sphere_no_sphere_is_one_clear_error(image):
    with pytest.raises(ValueError, match="no sphere-like circle"):
        so.locate_sphere(image)


def test_refine_sphere_snaps_an_off_circle():
    img = render_probe_photo("black", BALL_LIGHT)
    truth = outline_circle(BALL, CAM_SMALL)
    (tx, ty), tr = truth
    drawn = ((tx - 2.0, ty + 1.5), tr - 2.0)
    off = lp.light_from_sphere(img, *drawn, camera=CAM_SMALL)
    assert _angle_deg(off.direction, BALL_LIGHT) > 2.0  # what an off circle costs
    found = so.refine_sphere(img, *drawn, camera=CAM_SMALL, search_px=4.0)
    dc, dr = _circle_error(found, truth)
    assert dc < 0.1 and dr < 0.1
    res = lp.light_from_sphere(img, *found, camera=CAM_SMALL)
    assert _angle_deg(res.direction, BALL_LIGHT) < TOL_DEG
    with pytest.raises(ValueError, match="no sphere outline found"):
        so.refine_sphere(img, (40.0, 40.0), 20.0, camera=CAM_SMALL)  # on the wall


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda img: so.locate_sphere(img, radius_range_px=(50.0, 20.0)), "radius_range_px"),
        (lambda img: so.locate_sphere(img, background=np.zeros((10, 10))), "background"),
        (lambda img: so.locate_sphere(img[:10, :10]), "too small"),
        (lambda img: so.locate_sphere(np.where(img > 0.3, np.nan, img)), "NaN"),
        (lambda img: so.locate_sphere(img, camera="fisheye"), "camera"),
        (lambda img: so.refine_sphere(img, (160.0, 120.0), 60.0, search_px=0.1), "search_px"),
    ],
    ids=["radius_range", "background_shape", "too_small", "nan", "camera", "search"],
)
def test_locate_and_refine_argument_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call(render_probe_photo("black", BALL_LIGHT, noise=0.0))
