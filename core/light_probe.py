"""Distant-light direction from a photo of a mirror or glossy black sphere (METHOD §7).

A distant light seen in a mirror sphere shows as a highlight where the sphere's
normal n bisects the view direction v and the light direction l, so
``l = 2 (n . v) n - v``. Returning n itself (a common bug) is right only for a
light at the camera.

Image conventions: pixel coordinates are (x, y) = (column, row), row 0 at the
top, with pixel centres at integer coordinates. Camera space: the camera looks
down -z, +y is up, +x is right (as in Blender). All returned directions point
from the sphere towards the light and are unit float64 (3,) vectors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

_LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights for linear RGB


@dataclass(frozen=True)
class PerspectiveCamera:
    """Pinhole intrinsics in pixels: focal length and principal point (x, y)."""

    focal_px: float
    principal_px: tuple[float, float]


@dataclass(frozen=True)
class LightProbeResult:
    """What `light_from_sphere` found.

    direction: (3,) unit, camera space, towards the light.
    direction_world: (3,) unit, world space, or None if no rotation was given.
    normal: (3,) unit, camera space, the sphere normal at the highlight (NOT the light).
    highlight_px: (x, y) highlight centroid in pixels.
    uncertainty_rad: rough 1-sigma angular uncertainty of `direction` (radians).
    """

    direction: np.ndarray
    direction_world: np.ndarray | None
    normal: np.ndarray
    highlight_px: tuple[float, float]
    uncertainty_rad: float


def find_highlight(
    image, center_px, radius_px, *, percentile: float = 99.0, peak_fraction: float = 0.5
):
    """Locate the specular highlight inside the sphere's image disc.

    image: (H, W) or (H, W, C) linear radiance, C >= 3 (RGB used as Rec. 709 luminance).
    center_px, radius_px: the sphere's image circle in pixels.

    Only pixels whose centres lie inside the disc are searched. A pixel is
    bright if its luminance is at least max(the `percentile`-th percentile of
    the disc, `peak_fraction` x the disc's peak): the percentile keeps a broad
    lobe down to its core, the peak fraction keeps a tiny highlight from
    dragging in the background. Bright pixels are grouped into 8-connected
    blobs; the largest blob (by area, ties by summed luminance) is taken, so a
    single hot pixel cannot win over a real highlight. A clipped highlight has
    a flat saturated core, whose centroid is then its geometric centre.

    Each pixel is weighted by its luminance above the threshold, so weights
    fall to zero at the blob's edge and the pixel-quantised cut-off does not
    bias the centroid; a flat (clipped) core gets equal weights.

    Returns ((x, y), covariance): the weighted centroid of the blob (pixels)
    and the blob's (2, 2) weighted covariance of (x, y) about it (pixels^2).
    Raises ValueError if the disc holds no distinct highlight.
    """
    lum = _luminance(image)
    cx, cy, r = _check_circle(center_px, radius_px)
    if not 0.0 < percentile <= 100.0:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    if not 0.0 < peak_fraction <= 1.0:
        raise ValueError(f"peak_fraction must be in (0, 1], got {peak_fraction}")
    rows, cols = np.indices(lum.shape)
    disc = (cols - cx) ** 2 + (rows - cy) ** 2 <= r * r
    if not disc.any():
        raise ValueError(
            f"the sphere circle (centre {(cx, cy)}, radius {r}) covers no pixel of the "
            f"{lum.shape[1]}x{lum.shape[0]} image"
        )
    values = lum[disc]
    if not np.all(np.isfinite(values)):
        raise ValueError("image has NaN or Inf inside the sphere's disc")
    peak = values.max()
    if peak <= 0.0:
        raise ValueError("no highlight found: the sphere's disc is black")
    threshold = max(np.percentile(values, percentile), peak_fraction * peak)
    bright = disc & (lum >= threshold)
    labels, n_blobs = ndimage.label(bright, structure=np.ones((3, 3), dtype=bool))
    index = np.arange(1, n_blobs + 1)
    areas = ndimage.sum_labels(bright, labels, index)
    sums = ndimage.sum_labels(lum, labels, index)
    best = index[np.lexsort((sums, areas))[-1]]
    blob = labels == best
    # A blob this large is a uniformly lit disc, not a highlight.
    if blob.sum() > 0.25 * disc.sum():
        raise ValueError(
            "no distinct highlight found on the sphere: its disc is nearly uniform "
            "(is the light in view, and are the centre and radius right?)"
        )
    w = lum[blob] - threshold
    if not w.sum() > 0.0:  # a flat, clipped core
        w = np.ones_like(w)
    xy = np.stack([cols[blob], rows[blob]]).astype(np.float64)
    hx, hy = np.average(xy, axis=1, weights=w)
    cov = np.atleast_2d(np.cov(xy, aweights=w, bias=True)) if w.size > 1 else np.zeros((2, 2))
    return (float(hx), float(hy)), cov


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
    off-axis sphere, so fit with `detect_sphere(mask, camera=camera)`.
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
                f"(centre ({cx:.1f}, {cy:.1f}), radius {r:.1f}); check the centre and radius"
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
                f"(centre ({cx:.1f}, {cy:.1f}), radius {r:.1f}); check the centre and radius"
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
    peak_fraction: float = 0.5,
) -> LightProbeResult:
    """Direction towards a distant light from an image of a mirror or glossy black sphere.

    image: (H, W) or (H, W, C>=3) linear radiance. center_px: (x, y) and
    radius_px: the sphere's image circle in pixels (see `detect_sphere`).
    camera: None/"orthographic" or a `PerspectiveCamera` (see
    `light_from_highlight`). camera_to_world: optional (3, 3) rotation taking
    camera-space vectors to world space (Blender: the camera object's
    rotation matrix), to also return the world-space direction.

    The highlight is found by `find_highlight`. The uncertainty is the largest
    angle the result turns when the highlight moves by one standard deviation
    of the blob (plus half a pixel in quadrature) along either principal axis
    of the blob's covariance: a scale for the highlight's angular extent (the
    light's size and the surface's gloss), not a calibrated error bar on the
    centroid, which is usually much better.
    """
    rotation = None if camera_to_world is None else _check_rotation(camera_to_world)
    (hx, hy), cov = find_highlight(
        image, center_px, radius_px, percentile=percentile, peak_fraction=peak_fraction
    )
    l, n = light_from_highlight((hx, hy), center_px, radius_px, camera)
    cx, cy, r = _check_circle(center_px, radius_px)
    variances, axes = np.linalg.eigh(cov)
    angles = []
    for var, axis in zip(variances, axes.T, strict=True):
        step = np.sqrt(max(var, 0.0) + 0.25) * axis
        for sign in (1.0, -1.0):
            sx, sy = _clamp_to_disc(hx + sign * step[0], hy + sign * step[1], cx, cy, r)
            try:
                l2, _ = light_from_highlight((sx, sy), center_px, radius_px, camera)
            except ValueError:
                continue
            angles.append(np.arccos(np.clip(l @ l2, -1.0, 1.0)))
    uncertainty = float(max(angles)) if angles else float("nan")
    world = None if rotation is None else rotation @ l
    return LightProbeResult(
        direction=l,
        direction_world=world,
        normal=n,
        highlight_px=(hx, hy),
        uncertainty_rad=uncertainty,
    )


def detect_sphere(mask, threshold: float | None = None, camera=None):
    """Fit the sphere's image circle to the boundary of a mask.

    mask: (H, W) bool, True on the sphere. A non-bool (H, W) or (H, W, C)
    image is thresholded at `threshold` (default: halfway between its
    luminance minimum and maximum).
    camera: None/"orthographic", or a `PerspectiveCamera`.

    Boundary points are the midpoints between 4-adjacent pixel centres that
    straddle the mask edge, so they sit on the edge with no half-pixel bias.

    Orthographic: the algebraic least-squares circle (Kasa 1976): minimise
    sum (x^2 + y^2 + D x + E y + F)^2, a linear problem; centre (-D/2, -E/2),
    radius sqrt(cx^2 + cy^2 - F). It is biased towards small circles only
    when the boundary is a short arc; use whole-disc masks.

    Perspective: an off-axis sphere's outline is an ellipse, and a circle fit
    to it can cost degrees for lights near grazing. Instead the tangent cone
    is fitted: every boundary ray d satisfies d . a = cos(alpha) for the cone
    axis a and half-angle alpha, so w = a / cos(alpha) solves the linear
    least-squares problem d_i . w = 1. The returned circle passes through the
    two ends of the outline's major axis, which is the circle
    `light_from_highlight` turns back into exactly this sphere.

    Returns ((cx, cy), radius) in pixels.
    """
    m = np.asarray(mask)
    if m.dtype != bool:
        lum = _luminance(m)
        if not np.all(np.isfinite(lum)):
            raise ValueError("mask image has NaN or Inf")
        t = 0.5 * (lum.min() + lum.max()) if threshold is None else float(threshold)
        m = lum > t
    elif m.ndim != 2:
        raise ValueError(f"mask must have shape (H, W), got {m.shape}")
    rows, cols = np.indices(m.shape)
    h_edge = m[:, :-1] != m[:, 1:]
    v_edge = m[:-1, :] != m[1:, :]
    x = np.concatenate([cols[:, :-1][h_edge] + 0.5, cols[:-1, :][v_edge]]).astype(np.float64)
    y = np.concatenate([rows[:, :-1][h_edge], rows[:-1, :][v_edge] + 0.5]).astype(np.float64)
    if x.size < 3:
        raise ValueError("mask has no usable boundary: it is empty or fills the image")
    if camera is None or (isinstance(camera, str) and camera == "orthographic"):
        return _kasa_circle(x, y)
    if not isinstance(camera, PerspectiveCamera):
        raise ValueError(
            f"camera must be None, 'orthographic' or a PerspectiveCamera, got {camera!r}"
        )
    f, (px, py) = _check_camera(camera)
    d = np.stack([(x - px) / f, -(y - py) / f, -np.ones_like(x)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    w, *_ = np.linalg.lstsq(d, np.ones(len(d)), rcond=None)
    norm = np.linalg.norm(w)
    if not norm > 1.0:
        raise ValueError("mask boundary is not the outline of a sphere in front of the camera")
    return _major_axis_circle(w / norm, np.arccos(1.0 / norm), f, px, py)


def _kasa_circle(x, y):
    x0, y0 = x.mean(), y.mean()  # centre the data for a well-conditioned solve
    u, w = x - x0, y - y0
    a = np.column_stack([u, w, np.ones_like(u)])
    (d, e, f), *_ = np.linalg.lstsq(a, -(u * u + w * w), rcond=None)
    r2 = (d * d + e * e) / 4.0 - f
    if not r2 > 0.0:
        raise ValueError("mask boundary is not circular enough to fit a circle")
    return (float(x0 - d / 2.0), float(y0 - e / 2.0)), float(np.sqrt(r2))


def _major_axis_circle(axis, alpha, f, px, py):
    """Image circle through the ends of the outline's major axis of a cone (axis, alpha)."""
    if axis[2] >= 0.0 or alpha >= np.pi / 2:
        raise ValueError("the fitted sphere is not in front of the camera")
    k = np.cross(axis, [0.0, 0.0, -1.0])  # rotate within the plane holding the optical axis
    k = k / np.linalg.norm(k) if np.linalg.norm(k) > 1e-12 else np.array([0.0, 1.0, 0.0])
    ends = []
    for a in (alpha, -alpha):
        p = axis * np.cos(a) + np.cross(k, axis) * np.sin(a)  # Rodrigues, k is normal to axis
        if p[2] >= 0.0:
            raise ValueError("the sphere's outline reaches behind the camera")
        ends.append([px + f * p[0] / -p[2], py - f * p[1] / -p[2]])
    ends = np.array(ends)
    c = ends.mean(axis=0)
    return (float(c[0]), float(c[1])), float(np.linalg.norm(ends[0] - ends[1]) / 2.0)


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


def _luminance(image) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] >= 3:
        return img[..., :3] @ _LUMA
    raise ValueError(f"image must have shape (H, W) or (H, W, C>=3), got {img.shape}")


def _check_point(p, name: str):
    a = np.asarray(p, dtype=np.float64)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (x, y) pair in pixels, got {p!r}")
    return float(a[0]), float(a[1])


def _check_circle(center_px, radius_px):
    cx, cy = _check_point(center_px, "center_px")
    r = float(radius_px)
    if not (np.isfinite(r) and r > 0.0):
        raise ValueError(f"radius_px must be a positive finite number of pixels, got {radius_px!r}")
    return cx, cy, r


def _check_camera(camera: PerspectiveCamera):
    f = float(camera.focal_px)
    if not (np.isfinite(f) and f > 0.0):
        raise ValueError(f"camera.focal_px must be positive and finite, got {camera.focal_px!r}")
    return f, _check_point(camera.principal_px, "camera.principal_px")


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
