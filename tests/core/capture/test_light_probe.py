"""Light direction from a mirror sphere (core.capture.light_probe): synthetic renders with a known
distant light. The renderers here serve tests/test_core_sphere_outline.py too."""

import numpy as np
import pytest

from brdf_reconstruct.core.capture import light_probe as lp

LOBE = 0.0005  # radiance = exp(-(1 - r.l) / LOBE), a narrow lobe about the light
SS = 4  # supersampling per axis, so highlight centroids are not pixel-quantised
TOL_DEG = 0.5


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0)))


def _grazing(angle_from_view_deg, roll_deg):
    t, p = np.radians(angle_from_view_deg), np.radians(roll_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _subsamples(shape):
    rows, cols = np.indices(shape, dtype=np.float64)
    for i in range(SS):
        for j in range(SS):
            yield cols + (j + 0.5) / SS - 0.5, rows + (i + 0.5) / SS - 0.5


def render_orthographic(l, shape=(448, 448), center=(220.3, 226.6), radius=200.0, gain=1.0):
    """Mirror sphere under a distant light l (camera space), orthographic view v = +z."""
    l = _unit(l)
    img = np.zeros(shape)
    for x, y in _subsamples(shape):
        nx, ny = (x - center[0]) / radius, -(y - center[1]) / radius
        inside = nx**2 + ny**2 < 1.0
        nz = np.sqrt(np.clip(1.0 - nx**2 - ny**2, 0.0, None))
        # r = 2 (n.v) n - v with v = (0, 0, 1)
        r = np.stack([2 * nz * nx, 2 * nz * ny, 2 * nz * nz - 1.0], axis=-1)
        img += np.where(inside, gain * np.exp(-(1.0 - r @ l) / LOBE), 0.0)
    return img / SS**2


def render_perspective(l, centre, cam, shape=(480, 640), radius=1.0):
    """Mirror sphere (camera-space centre, radius) seen by a pinhole camera; also its coverage."""
    l, centre = _unit(l), np.asarray(centre, dtype=np.float64)
    f, (px, py) = cam.focal_px, cam.principal_px
    img, cover = np.zeros(shape), np.zeros(shape)
    for x, y in _subsamples(shape):
        d = np.stack([(x - px) / f, -(y - py) / f, -np.ones_like(x)], axis=-1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        b = d @ centre
        disc = b * b - (centre @ centre - radius**2)
        hit = disc > 0.0
        t = b - np.sqrt(np.clip(disc, 0.0, None))
        n = (t[..., None] * d - centre) / radius
        r = d - 2.0 * np.sum(n * d, axis=-1, keepdims=True) * n  # reflect v = -d
        img += np.where(hit, np.exp(-(1.0 - r @ l) / LOBE), 0.0)
        cover += hit
    return img / SS**2, cover / SS**2 > 0.5


def outline_circle(centre, cam, radius=1.0):
    """Image circle through the two ends of the outline's major axis (exact for the method)."""
    c = np.asarray(centre, dtype=np.float64)
    dist = np.linalg.norm(c)
    alpha = np.arcsin(radius / dist)
    axis = c / dist
    k = np.cross(axis, [0.0, 0.0, -1.0])
    k = k / np.linalg.norm(k) if np.linalg.norm(k) > 1e-12 else np.array([0.0, 1.0, 0.0])

    def rotate(v, a):  # Rodrigues
        return v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * (k @ v) * (1 - np.cos(a))

    pts = []
    for a in (alpha, -alpha):
        p = rotate(axis, a)
        pts.append(
            [
                cam.principal_px[0] + cam.focal_px * p[0] / -p[2],
                cam.principal_px[1] - cam.focal_px * p[1] / -p[2],
            ]
        )
    pts = np.array(pts)
    return tuple(pts.mean(axis=0)), float(np.linalg.norm(pts[0] - pts[1]) / 2)


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


CAM = lp.PerspectiveCamera(focal_px=800.0, principal_px=(319.5, 239.5))
SPHERE_CENTRES = {
    "on_axis": [0.0, 0.0, -6.0],
    "off_axis": [1.0, -0.6, -6.0],
}
PERSP_LIGHTS = {
    "upper_right": [0.5, 0.3, 0.8],
    "lower_left": [-0.6, -0.2, 0.5],
    "near_grazing_140deg": _grazing(140.0, -60.0),
}


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


def _frame_with_z(z):
    """Rotation whose third column is unit z (any completion)."""
    z = _unit(z)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = _unit(np.cross(a, z))
    return np.column_stack([x, np.cross(z, x), z])


# --- probe photos: an off-axis ball (the outline tests use them too) ---------------

CAM_SMALL = lp.PerspectiveCamera(focal_px=400.0, principal_px=(159.5, 119.5))
BALL = np.array([0.9, -0.5, -6.5])  # off-axis: the outline is an ellipse
BALL_LIGHT = _frame_with_z(-_unit(BALL)) @ _unit([0.5, 0.4, 0.75])  # 48 degrees off the view


def render_probe_photo(kind, l, centre=BALL, cam=CAM_SMALL, shape=(240, 320), background=0.4,
                       gain=200.0, noise=0.003, seed=0):
    """A probe photo: a sphere (radius 1) in front of a plain background.

    kind "black": a glossy black ball (0.02 plus 4 % of a sky and the light's lobe);
    "chrome": a mirror showing a sky (0.3 to 0.5, brighter up) and the lobe.
    background: a number, or an (H, W) array. Gaussian noise of `noise` is added.
    """
    l, centre = _unit(l), np.asarray(centre, dtype=np.float64)
    f, (px, py) = cam.focal_px, cam.principal_px
    img = np.zeros(shape)
    for x, y in _subsamples(shape):
        d = np.stack([(x - px) / f, -(y - py) / f, -np.ones_like(x)], axis=-1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        b = d @ centre
        disc = b * b - (centre @ centre - 1.0)
        hit = disc > 0.0
        n = (b - np.sqrt(np.clip(disc, 0.0, None)))[..., None] * d - centre
        r = d - 2.0 * np.sum(n * d, axis=-1, keepdims=True) * n
        sky = 0.4 + 0.1 * r[..., 1]
        lobe = gain * np.exp(-(1.0 - r @ l) / LOBE)
        sphere = 0.02 + 0.04 * (sky + lobe) if kind == "black" else sky + lobe
        img += np.where(hit, sphere, background)
    img /= SS**2
    return img + np.random.default_rng(seed).normal(0.0, noise, shape)


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
