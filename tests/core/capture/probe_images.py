"""Synthetic sphere-probe images with a known sphere and light, for the light-probe
and sphere-outline tests (test_light_probe.py, test_sphere_outline.py; no bpy).

Camera space looks down -z with +y up; image rows grow downwards. A mirror
sphere reflects a narrow lobe about the light, radiance exp(-(1 - r.l) / LOBE),
supersampled SS x SS per pixel so highlight centroids are not pixel-quantised.
"""

import numpy as np

from brdf_reconstruct.core.capture import light_probe as lp

LOBE = 0.0005  # radiance = exp(-(1 - r.l) / LOBE), a narrow lobe about the light
SS = 4  # supersampling per axis, so highlight centroids are not pixel-quantised
TOL_DEG = 0.5  # the light-direction error the tests allow, degrees


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(unit(a) @ unit(b), -1.0, 1.0)))


def grazing(angle_from_view_deg, roll_deg):
    t, p = np.radians(angle_from_view_deg), np.radians(roll_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def subsamples(shape):
    rows, cols = np.indices(shape, dtype=np.float64)
    for i in range(SS):
        for j in range(SS):
            yield cols + (j + 0.5) / SS - 0.5, rows + (i + 0.5) / SS - 0.5


def render_orthographic(l, shape=(448, 448), center=(220.3, 226.6), radius=200.0, gain=1.0):
    """Mirror sphere under a distant light l (camera space), orthographic view v = +z."""
    l = unit(l)
    img = np.zeros(shape)
    for x, y in subsamples(shape):
        nx, ny = (x - center[0]) / radius, -(y - center[1]) / radius
        inside = nx**2 + ny**2 < 1.0
        nz = np.sqrt(np.clip(1.0 - nx**2 - ny**2, 0.0, None))
        # r = 2 (n.v) n - v with v = (0, 0, 1)
        r = np.stack([2 * nz * nx, 2 * nz * ny, 2 * nz * nz - 1.0], axis=-1)
        img += np.where(inside, gain * np.exp(-(1.0 - r @ l) / LOBE), 0.0)
    return img / SS**2


def render_perspective(l, centre, cam, shape=(480, 640), radius=1.0):
    """Mirror sphere (camera-space centre, radius) seen by a pinhole camera; also its coverage."""
    l, centre = unit(l), np.asarray(centre, dtype=np.float64)
    f, (px, py) = cam.focal_px, cam.principal_px
    img, cover = np.zeros(shape), np.zeros(shape)
    for x, y in subsamples(shape):
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


def frame_with_z(z):
    """Rotation whose third column is unit z (any completion)."""
    z = unit(z)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = unit(np.cross(a, z))
    return np.column_stack([x, np.cross(z, x), z])


# --- a pinhole camera, spheres off and on its axis, lights relative to the view ---------

CAM = lp.PerspectiveCamera(focal_px=800.0, principal_px=(319.5, 239.5))
SPHERE_CENTRES = {
    "on_axis": [0.0, 0.0, -6.0],
    "off_axis": [1.0, -0.6, -6.0],
}
PERSP_LIGHTS = {
    "upper_right": [0.5, 0.3, 0.8],
    "lower_left": [-0.6, -0.2, 0.5],
    "near_grazing_140deg": grazing(140.0, -60.0),
}


# --- probe photos: an off-axis ball ---------------------------------------------------

CAM_SMALL = lp.PerspectiveCamera(focal_px=400.0, principal_px=(159.5, 119.5))
BALL = np.array([0.9, -0.5, -6.5])  # off-axis: the outline is an ellipse
BALL_LIGHT = frame_with_z(-unit(BALL)) @ unit([0.5, 0.4, 0.75])  # 48 degrees off the view


def render_probe_photo(kind, l, centre=BALL, cam=CAM_SMALL, shape=(240, 320), background=0.4,
                       gain=200.0, noise=0.003, seed=0):
    """A probe photo: a sphere (radius 1) in front of a plain background.

    kind "black": a glossy black ball (0.02 plus 4 % of a sky and the light's lobe);
    "chrome": a mirror showing a sky (0.3 to 0.5, brighter up) and the lobe.
    background: a number, or an (H, W) array. Gaussian noise of `noise` is added.
    """
    l, centre = unit(l), np.asarray(centre, dtype=np.float64)
    f, (px, py) = cam.focal_px, cam.principal_px
    img = np.zeros(shape)
    for x, y in subsamples(shape):
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
