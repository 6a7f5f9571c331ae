"""Distant-light direction from a photo of a mirror or glossy black sphere (METHOD §7).

A distant light seen in a mirror sphere shows as a highlight where the sphere's
normal n bisects the view direction v and the light direction l, so
``l = 2 (n . v) n - v``. Returning n itself (a common bug) is right only for a
light at the camera.

This module finds the highlight (`find_highlight`) and turns it into the light
(`light_from_highlight`, and `light_from_sphere` with its uncertainty), given
the sphere's image circle. The circle comes from `sphere_outline`: found in the
probe photo (`locate_sphere`), a hand-drawn circle snapped to the outline
(`refine_sphere`) or fitted to a mask (`detect_sphere`); those three, and
`PerspectiveCamera`, are re-exported here.

Image conventions: pixel coordinates are (x, y) = (column, row), row 0 at the
top, with pixel centres at integer coordinates. Camera space: the camera looks
down -z, +y is up, +x is right (as in Blender). All returned directions point
from the sphere towards the light and are unit float64 (3,) vectors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .sphere_outline import (
    PerspectiveCamera,
    _check_camera,
    _check_circle,
    _check_point,
    _luminance,
    detect_sphere,
    locate_sphere,
    refine_sphere,
)

__all__ = [
    "LightProbeResult",
    "PerspectiveCamera",
    "detect_sphere",
    "find_highlight",
    "light_from_highlight",
    "light_from_sphere",
    "locate_sphere",
    "refine_sphere",
]

_HIGHLIGHT_GROW = 2  # pixels the highlight's blob grows by for its centroid


@dataclass(frozen=True)
class LightProbeResult:
    """What `light_from_sphere` found.

    direction: (3,) unit, camera space, towards the light.
    direction_world: (3,) unit, world space, or None if no rotation was given.
    normal: (3,) unit, camera space, the sphere normal at the highlight (NOT the light).
    highlight_px: (x, y) highlight centroid in pixels.
    uncertainty_rad: angular uncertainty of `direction` (radians), about one standard
        deviation (see `light_from_sphere`).
    """

    direction: np.ndarray
    direction_world: np.ndarray | None
    normal: np.ndarray
    highlight_px: tuple[float, float]
    uncertainty_rad: float


def find_highlight(
    image, center_px, radius_px, *, percentile: float = 99.0, peak_fraction: float = 0.9
):
    """Locate the specular highlight inside the sphere's image disc.

    image: (H, W) or (H, W, C) linear radiance, C >= 3 (RGB used as Rec. 709 luminance).
    center_px, radius_px: the sphere's image circle in pixels.

    Only pixels whose centres lie inside the disc are searched, on a copy where
    each pixel is capped at its brightest 8-neighbour, so an isolated hot pixel
    sinks to its surroundings while a highlight (which the optics or the pixel
    filter spread over a neighbour or more) keeps its level. A pixel is bright
    if it reaches max(the `percentile`-th percentile of the disc,
    `peak_fraction` x the disc's peak): near the peak, so a clipped highlight's
    flat core is taken without the broad unclipped lobe a clear coat's base
    can put around it. Bright pixels are grouped into 8-connected blobs; the
    largest blob (by area, ties by summed luminance) is the highlight.

    The centroid is taken over the blob grown by 2 px (a highlight smaller than
    a pixel is spread over its neighbours, and a clipped one has a shoulder;
    the blob alone would quantise the centroid to whole pixels), each pixel
    weighted by its luminance above the brightest pixel of the 2 px ring around
    that (hot pixels capped), so weights fall to zero at the window's edge and its
    pixel-quantised outline does not bias the centroid. A clipped core gets equal
    weights: its centroid is its geometric centre.

    Returns ((x, y), covariance): the weighted centroid (pixels) and the (2, 2)
    weighted covariance of (x, y) about it (pixels^2).
    Raises ValueError if the disc holds no distinct highlight.
    """
    (hx, hy), cov, _ = _highlight(image, center_px, radius_px, percentile, peak_fraction)
    return (hx, hy), cov


def _highlight(image, center_px, radius_px, percentile, peak_fraction):
    """`find_highlight`, plus the effective number of pixels in the centroid."""
    lum = _luminance(image)
    cx, cy, r = _check_circle(center_px, radius_px)
    if not 0.0 < percentile <= 100.0:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    if not 0.0 < peak_fraction <= 1.0:
        raise ValueError(f"peak_fraction must be in (0, 1], got {peak_fraction}")
    height, width = lum.shape
    # only the disc's bounding box is looked at (probe photos can be large)
    y0, x0 = max(0, int(np.floor(cy - r))), max(0, int(np.floor(cx - r)))
    y1, x1 = min(height, int(np.ceil(cy + r)) + 1), min(width, int(np.ceil(cx + r)) + 1)
    lum = lum[y0:max(y0, y1), x0:max(x0, x1)]
    rows, cols = np.indices(lum.shape)
    rows, cols = rows + y0, cols + x0
    disc = (cols - cx) ** 2 + (rows - cy) ** 2 <= r * r
    if not disc.any():
        raise ValueError(
            f"the sphere circle (center {(cx, cy)}, radius {r}) covers no pixel of the "
            f"{width}x{height} image"
        )
    values = lum[disc]
    if not np.all(np.isfinite(values)):
        raise ValueError("image has NaN or Inf inside the sphere's disc")
    if values.max() <= 0.0:
        raise ValueError("no highlight found: the sphere's disc is black")
    ring8 = np.ones((3, 3), dtype=bool)
    ring8[1, 1] = False
    capped = np.minimum(lum, ndimage.maximum_filter(lum, footprint=ring8, mode="nearest"))
    peak = capped[disc].max()
    threshold = max(np.percentile(capped[disc], percentile), peak_fraction * peak)
    bright = disc & (capped >= threshold)
    labels, n_blobs = ndimage.label(bright, structure=np.ones((3, 3), dtype=bool))
    index = np.arange(1, n_blobs + 1)
    areas = ndimage.sum_labels(bright, labels, index)
    sums = ndimage.sum_labels(capped, labels, index)
    best = index[np.lexsort((sums, areas))[-1]]
    blob = labels == best
    # A blob this large is a uniformly lit disc, not a highlight.
    if blob.sum() > 0.25 * disc.sum():
        raise ValueError(
            "no distinct highlight found on the sphere: its disc is nearly uniform "
            "(is the light in view, and are the center and radius right?)"
        )
    window = ndimage.binary_dilation(blob, iterations=_HIGHLIGHT_GROW) & disc
    ring = ndimage.binary_dilation(window, iterations=_HIGHLIGHT_GROW) & disc & ~window
    base = min(float(capped[ring].max()) if ring.any() else 0.0, threshold)
    w = np.clip(lum[window] - base, 0.0, None)
    if not w.sum() > 0.0:
        w = np.ones_like(w)
    xy = np.stack([cols[window], rows[window]]).astype(np.float64)
    hx, hy = np.average(xy, axis=1, weights=w)
    cov = np.atleast_2d(np.cov(xy, aweights=w, bias=True)) if w.size > 1 else np.zeros((2, 2))
    n_eff = float(w.sum() ** 2 / np.sum(w * w))
    return (float(hx), float(hy)), cov, n_eff


def light_from_highlight(highlight_px, center_px, radius_px, camera=None):
    """Light direction and sphere normal from a highlight position.

    highlight_px: (x, y) pixels; center_px: (x, y) pixels; radius_px: pixels.
    camera: None or "orthographic" for an orthographic view, or a
    `PerspectiveCamera`.

    Orthographic: n = ((hx - cx)/r, -(hy - cy)/r, sqrt(1 - nx^2 - ny^2)),
    v = (0, 0, 1), l = 2 (n . v) n - v.

    Perspective: the sphere (radius 1; the scale cancels) is placed on the ray
    through the circle centre, at the distance where it subtends the circle's
    angular radius. That half-angle is half the angle between the rays through
    the two circle points c +/- r u, u pointing away from the principal point.
    This is exact when the given circle matches the major axis of the
    sphere's (slightly elliptical) outline; a circle fitted to the outline
    lies between its axes and can cost degrees for lights near grazing on an
    off-axis sphere, so fit with `locate_sphere(image, camera)`,
    `refine_sphere(..., camera)` or `detect_sphere(mask, camera=camera)`.
    The highlight ray is intersected with the sphere: n = P - C, v = -ray,
    l = 2 (n . v) n - v.

    Returns (l, n): (3,) unit camera-space vectors. Raises ValueError if the
    highlight falls outside the sphere's disc (or its ray misses the sphere).
    """
    hx, hy = _check_point(highlight_px, "highlight_px")
    cx, cy, r = _check_circle(center_px, radius_px)
    if camera is None or (isinstance(camera, str) and camera == "orthographic"):
        nx, ny = (hx - cx) / r, -(hy - cy) / r
        rho2 = nx * nx + ny * ny
        if rho2 > 1.0 + 1e-9:
            raise ValueError(
                f"the highlight at ({hx:.1f}, {hy:.1f}) px lies outside the sphere's disc "
                f"(center ({cx:.1f}, {cy:.1f}), radius {r:.1f}); check the center and radius"
            )
        n = np.array([nx, ny, np.sqrt(max(0.0, 1.0 - rho2))])
        n /= np.linalg.norm(n)
        v = np.array([0.0, 0.0, 1.0])
    elif isinstance(camera, PerspectiveCamera):
        f, (px, py) = _check_camera(camera)
        centre = _sphere_centre(cx, cy, r, f, px, py)
        d = _ray(hx, hy, f, px, py)
        b = float(d @ centre)
        disc = b * b - (float(centre @ centre) - 1.0)
        if disc < -1e-9:
            raise ValueError(
                f"the highlight at ({hx:.1f}, {hy:.1f}) px lies outside the sphere's disc "
                f"(center ({cx:.1f}, {cy:.1f}), radius {r:.1f}); check the center and radius"
            )
        point = (b - np.sqrt(max(disc, 0.0))) * d  # the near intersection
        n = point - centre
        n /= np.linalg.norm(n)
        v = -d
    else:
        raise ValueError(
            f"camera must be None, 'orthographic' or a PerspectiveCamera, got {camera!r}"
        )
    l = 2.0 * float(n @ v) * n - v
    return l / np.linalg.norm(l), n


def light_from_sphere(
    image,
    center_px,
    radius_px,
    camera=None,
    camera_to_world=None,
    *,
    percentile: float = 99.0,
    peak_fraction: float = 0.9,
    circle_sigma_px: float = 0.25,
) -> LightProbeResult:
    """Direction towards a distant light from an image of a mirror or glossy black sphere.

    image: (H, W) or (H, W, C>=3) linear radiance. center_px: (x, y) and
    radius_px: the sphere's image circle in pixels (see `locate_sphere`; a
    circle drawn by hand should go through `refine_sphere` first).
    camera: None/"orthographic" or a `PerspectiveCamera` (see
    `light_from_highlight`). camera_to_world: optional (3, 3) rotation taking
    camera-space vectors to world space (Blender: the camera object's
    rotation matrix), to also return the world-space direction.
    circle_sigma_px: the circle's uncertainty in pixels (centre and radius),
    for `uncertainty_rad`: 0.25 suits `locate_sphere`, which finds a chrome
    sphere's outline to about 0.05 px and a glossy black one's about 0.4 px
    inside the limb (its Fresnel-bright rim fades into the background there);
    give the error of a hand-drawn circle that is not refined.

    The highlight is found by `find_highlight`. The uncertainty (radians) adds
    in quadrature the largest turn of the result when the highlight moves by
    sigma_h along either principal axis of its covariance C, and the turns when
    the circle's centre moves by circle_sigma_px in x, in y and its radius
    changes by as much. sigma_h = sqrt(lambda_max(C) + 1/12 px^2) / n_eff, with
    n_eff the effective number of pixels of the centroid's weights: an
    empirical law measured on Cycles renders (bench/probe_bench.py), where a
    sub-pixel highlight (n_eff about 2) is placed to about 0.2 px and a clipped
    core (n_eff 10 to 20) to about 0.05 px. On 88 such photos (chrome and black
    spheres of 71 to 178 px radius, lights 10 to 75 degrees off the view, HDR
    and clipped) the error was below the uncertainty in 70 to 100 % of each
    set-up and below twice it in every case (bench/results/light_probe.json).
    """
    rotation = None if camera_to_world is None else _check_rotation(camera_to_world)
    sigma_c = float(circle_sigma_px)
    if not (np.isfinite(sigma_c) and sigma_c >= 0.0):
        raise ValueError(f"circle_sigma_px must be a finite number >= 0, got {circle_sigma_px!r}")
    (hx, hy), cov, n_eff = _highlight(image, center_px, radius_px, percentile, peak_fraction)
    l, n = light_from_highlight((hx, hy), center_px, radius_px, camera)
    cx, cy, r = _check_circle(center_px, radius_px)

    def turn(h, c, radius):
        """Angle (rad) between l and the light for a perturbed highlight or circle."""
        try:
            l2, _ = light_from_highlight(h, c, radius, camera)
        except ValueError:  # pushed off the disc: the other sign is tried
            return None
        return float(np.arccos(np.clip(l @ l2, -1.0, 1.0)))

    variances, axes = np.linalg.eigh(cov)
    sigma_h = np.sqrt(max(variances[-1], 0.0) + 1.0 / 12.0) / n_eff
    moved = [
        turn(_clamp_to_disc(hx + sign * sigma_h * a[0], hy + sign * sigma_h * a[1], cx, cy, r),
             (cx, cy), r)
        for a in axes.T
        for sign in (1.0, -1.0)
    ]
    total = max([t for t in moved if t is not None], default=0.0) ** 2
    for dx, dy, dr in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)):
        turns = [
            turn((hx, hy), (cx + s * dx * sigma_c, cy + s * dy * sigma_c), r + s * dr * sigma_c)
            for s in (1.0, -1.0)
        ]
        total += max([t for t in turns if t is not None], default=0.0) ** 2
    world = None if rotation is None else rotation @ l
    return LightProbeResult(
        direction=l,
        direction_world=world,
        normal=n,
        highlight_px=(hx, hy),
        uncertainty_rad=float(np.sqrt(total)),
    )


def _ray(x, y, f, px, py) -> np.ndarray:
    """Unit camera-space ray through pixel (x, y) of a pinhole camera looking down -z."""
    d = np.array([(x - px) / f, -(y - py) / f, -1.0])
    return d / np.linalg.norm(d)


def _sphere_centre(cx, cy, r, f, px, py) -> np.ndarray:
    """Camera-space centre of a unit sphere whose image circle is (cx, cy), r."""
    u = np.array([cx - px, cy - py])
    norm = np.linalg.norm(u)
    u = u / norm if norm > 1e-12 else np.array([1.0, 0.0])
    a = _ray(cx + r * u[0], cy + r * u[1], f, px, py)
    b = _ray(cx - r * u[0], cy - r * u[1], f, px, py)
    half_angle = 0.5 * np.arccos(np.clip(a @ b, -1.0, 1.0))
    axis = (a + b) / np.linalg.norm(a + b)
    return axis / np.sin(half_angle)


def _clamp_to_disc(x, y, cx, cy, r):
    dx, dy = x - cx, y - cy
    rho = np.hypot(dx, dy)
    if rho <= r:
        return x, y
    s = r / rho * (1.0 - 1e-9)
    return cx + dx * s, cy + dy * s


def _check_rotation(m) -> np.ndarray:
    r = np.asarray(m, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError(f"camera_to_world must be a finite (3, 3) rotation, got shape {r.shape}")
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0.0:
        raise ValueError(
            "camera_to_world must be a rotation (orthonormal, det +1); "
            "remove scale from the camera matrix first"
        )
    return r
