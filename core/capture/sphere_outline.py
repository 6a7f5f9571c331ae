"""The probe sphere's image circle in a photo (METHOD §7).

`light_probe` turns the highlight on a mirror or glossy black sphere into the
light's direction; it needs the sphere's image circle, which comes from here:

- `locate_sphere`: from the probe photo itself (edges, a coarse gradient Hough
  vote and a sub-pixel fit of the outline), for a chrome sphere or a black one,
  brighter or darker than the wall behind it;
- `refine_sphere`: a circle drawn by hand (or found roughly) snapped to the
  sphere's outline;
- `detect_sphere`: a circle fitted to the boundary of a mask.

Orthographic views get the algebraic least-squares circle (Kasa). With a
`PerspectiveCamera` an off-axis sphere's outline is an ellipse, so the sphere's
tangent cone is fitted instead and the circle returned is the one through the
ends of the outline's major axis: the circle `light_probe.light_from_highlight`
turns back into exactly that sphere.

The module also holds what `light_probe` shares with it: `PerspectiveCamera`,
Rec. 709 luminance and the argument checks.

Image conventions: pixel coordinates are (x, y) = (column, row), row 0 at the
top, with pixel centres at integer coordinates. Camera space: the camera looks
down -z, +y is up, +x is right (as in Blender). A circle is ((cx, cy), radius)
in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

_LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights for linear RGB
_COARSE_PX = 400  # the coarse circle search runs on at most this many pixels across
_MIN_COVERAGE = 0.6  # edge pixels per pixel of circumference (spheres: 1.1; a square: 0.45)
_EDGE_MIN = 0.01  # smallest log-luminance gradient taken as an edge (about a 2.5 % step)
_N_CANDIDATES = 8  # vote peaks whose circles are compared
_CENTRE_SLACK = 4  # coarse pixels a vote's peak may be off the circle's centre
_EDGE_SIGMA = 0.35  # px, the Gaussian derivative along a ray (the outline's own blur ~0.5 px)
_OUTLINE_POINTS = 720  # points of a fitted outline, for the next search


@dataclass(frozen=True)
class PerspectiveCamera:
    """Pinhole intrinsics in pixels: focal length and principal point (x, y)."""

    focal_px: float
    principal_px: tuple[float, float]


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
    `light_probe.light_from_highlight` turns back into exactly this sphere.

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
    _check_camera_kind(camera)
    circle, _, _ = _fit_outline(x, y, camera)
    return circle


def locate_sphere(
    image,
    camera=None,
    *,
    background=None,
    radius_range_px: tuple[float, float] | None = None,
):
    """Find the probe sphere's image circle in the probe photo itself.

    image: (H, W) or (H, W, C>=3) linear radiance (RGB used as Rec. 709 luminance).
    camera: None/"orthographic", or a `PerspectiveCamera`; as for `detect_sphere`,
    the returned circle is the one `light_probe.light_from_highlight` turns
    back into the fitted sphere (through the ends of the outline's major axis).
    background: optional clean plate, the same view without the sphere, shape
    (H, W) or (H, W, C>=3) like `image`; the sphere is then sought where the
    two differ, which helps when the sphere's rim matches the wall behind it.
    radius_range_px: optional (min, max) radius in pixels of `image`; default
    3 % to 50 % of the image's smaller side.

    Works for a mirror (chrome) sphere and for a glossy black one, darker or
    brighter than its background, because it looks for edges, not for a level:

    1. coarse search (on a copy reduced to at most 400 px across): log
       luminance, a 3 x 3 median (hot pixels go), Gaussian blur (1 px) and
       thinned gradient edges; every edge pixel votes for centres along its
       gradient line, both ways (either polarity); at each strong centre the
       distances of the edge pixels whose gradient is radial give the radius:
       the OUTERMOST radius with a well covered circle, since everything
       inside a mirror sphere's outline is a reflection and can be a circle too;
       the centre whose circle has the most edge support wins (the highlight is
       small, and the sphere's shadow is an ellipse cut by the sphere);
    2. `refine_sphere` at full resolution.

    Returns ((cx, cy), radius) in pixels, with pixel centres at integer
    coordinates. Raises ValueError if the photo shows no sphere-like circle.
    """
    _check_camera_kind(camera)
    lum = _finite_luminance(image, "image")
    bg = _background_luminance(background, lum)
    h, w = lum.shape
    if min(h, w) < 16:
        raise ValueError(f"the probe photo is too small to find a sphere in ({w}x{h} pixels)")
    lo, hi = (0.03 * min(h, w), 0.5 * min(h, w)) if radius_range_px is None else radius_range_px
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and 2.0 <= lo < hi):
        raise ValueError(
            "radius_range_px must be (min, max) pixels with 2 <= min < max, "
            f"got {radius_range_px!r}"
        )
    scale = max(1, int(np.ceil(max(h, w) / _COARSE_PX)))
    coarse = _block_mean(lum, scale)
    coarse_bg = None if bg is None else _block_mean(bg, scale)
    found = _hough_circle(coarse, coarse_bg, lo / scale, hi / scale)
    if found is None:
        raise ValueError(
            "no sphere-like circle found in the probe photo; draw the sphere's circle instead"
        )
    (cx, cy), r = found
    # coarse pixel (i, j) covers fine pixels i*s .. i*s + s - 1
    center = ((cx + 0.5) * scale - 0.5, (cy + 0.5) * scale - 0.5)
    try:
        return refine_sphere(image, center, r * scale, camera, background=background,
                             search_px=max(3.0, 1.5 * scale))
    except ValueError:
        raise ValueError(
            "no sphere-like circle found in the probe photo: the best circle has no clean "
            "outline; draw the sphere's circle instead"
        ) from None


def refine_sphere(
    image,
    center_px,
    radius_px,
    camera=None,
    *,
    background=None,
    search_px: float = 3.0,
):
    """Snap an approximate sphere circle (found or drawn by hand) to the sphere's outline.

    image: (H, W) or (H, W, C>=3) linear radiance. center_px: (x, y) and
    radius_px: a circle within about `search_px` pixels of the outline.
    camera, background: as for `locate_sphere`.

    Along one ray per pixel of circumference from the centre, the luminance
    (or its difference from `background`) is sampled within +/- search_px of
    the circle, and the outline is put where it changes fastest (a parabola
    through the peak of the blurred derivative: sub-pixel, either polarity).
    The outline points are then fitted as in `detect_sphere` (a circle, or the
    sphere's tangent cone for a `PerspectiveCamera`), dropping points more than
    3 robust standard deviations off (the highlight on the rim, a hot pixel,
    low contrast where the rim matches the wall), and fitted again twice in a
    narrower band about the new circle.

    A hand-drawn circle off by d pixels on a sphere of radius r pixels turns
    the light by about 2 d / r radians (1.6 degrees for d = 1, r = 70), so
    pass a drawn circle through here before `light_probe.light_from_sphere`.

    Returns ((cx, cy), radius) in pixels. Raises ValueError if fewer than half
    the rays find an outline, or the outline points scatter like noise (the
    circle is not on a sphere).
    """
    lum = _finite_luminance(image, "image")
    if background is not None:
        lum = lum - _background_luminance(background, lum)
    cx, cy, r = _check_circle(center_px, radius_px)
    search = float(search_px)
    if not (np.isfinite(search) and 0.5 <= search < r):
        raise ValueError(
            f"search_px must be at least 0.5 pixel and below the radius {r:.1f}, got {search_px!r}"
        )
    _check_camera_kind(camera)
    outline = None  # the predicted outline, (M, 2) pixels, once fitted
    for band in (search, max(1.5, 0.5 * search), 1.5):
        x, y = _outline_points(lum, cx, cy, r, band, outline)
        ((cx, cy), r), outline = _robust_outline_fit(x, y, camera, _n_rays(r), band)
    return (cx, cy), r


def _hough_circle(lum, bg, rmin, rmax):
    """Coarse circle ((cx, cy), r) in pixels of `lum` by a gradient Hough vote, or None."""
    h, w = lum.shape
    signal = _log_luminance(lum)
    if bg is not None:
        signal = signal - _log_luminance(bg)
    signal = ndimage.gaussian_filter(ndimage.median_filter(signal, size=3), 1.0)
    gy, gx = ndimage.sobel(signal, axis=0) / 8.0, ndimage.sobel(signal, axis=1) / 8.0
    mag = np.hypot(gx, gy)
    edges = _thin_edges(mag, gx, gy)
    # a noise floor: most pixels are flat, so the median gradient is noise
    edges &= mag >= max(_EDGE_MIN, 6.0 * float(np.median(mag)))
    rows, cols = np.nonzero(edges)
    if rows.size < 8:
        return None
    ux, uy = gx[rows, cols] / mag[rows, cols], gy[rows, cols] / mag[rows, cols]
    radii = np.arange(max(1.0, np.floor(rmin)), np.ceil(rmax) + 1.0)
    votes = np.zeros(h * w)
    for sign in (1.0, -1.0):  # either polarity: the sphere darker or brighter than behind it
        vx = np.rint(cols[:, None] + sign * radii[None, :] * ux[:, None]).astype(np.int64)
        vy = np.rint(rows[:, None] + sign * radii[None, :] * uy[:, None]).astype(np.int64)
        ok = (vx >= 0) & (vx < w) & (vy >= 0) & (vy < h)
        votes += np.bincount(vy[ok] * w + vx[ok], minlength=h * w)
    votes = ndimage.gaussian_filter(votes.reshape(h, w), 1.0)
    peaks = (votes == ndimage.maximum_filter(votes, size=max(3, int(rmin)) | 1)) & (votes > 0)
    py_, px_ = np.nonzero(peaks)
    order = np.argsort(votes[py_, px_])[::-1][:_N_CANDIDATES]
    # The vote's peak can sit a few pixels off (reflections inside a mirror sphere
    # vote too), so each candidate centre is moved within +/- 4 px to the best support.
    offsets = np.arange(-_CENTRE_SLACK, _CENTRE_SLACK + 1.0)
    best = None
    for cy, cx in zip(py_[order], px_[order], strict=True):
        for oy in offsets:
            for ox in offsets:
                circle = _outermost_radius(cols, rows, ux, uy, cx + ox, cy + oy, rmin, rmax)
                if circle is not None and (best is None or circle[1] > best[1]):
                    best = circle
    if best is None:
        return None
    (cx, cy, r), _ = best
    # then a circle through the edge pixels on it, in narrowing bands (sub-pixel)
    for band in (2.0, 1.0):
        dx, dy = cols - cx, rows - cy
        dist = np.hypot(dx, dy)
        with np.errstate(invalid="ignore", divide="ignore"):
            on = (np.abs(dist - r) <= band) & (
                np.abs(dx * ux + dy * uy) >= np.cos(np.radians(25.0)) * dist
            )
        if on.sum() < 8:
            break
        (cx, cy), r = _kasa_circle(cols[on].astype(np.float64), rows[on].astype(np.float64))
    return (float(cx), float(cy)), float(r)


def _outermost_radius(cols, rows, ux, uy, cx, cy, rmin, rmax):
    """The outermost well-covered circle about (cx, cy): ((cx, cy, r), support) or None.

    Edge pixels whose gradient is radial (within 25 degrees) are binned by distance;
    a radius is covered if its +/- 1 px ring holds at least _MIN_COVERAGE x 2 pi r
    such pixels. Everything inside a mirror sphere's outline is a reflection that can
    be circular too, so the largest covered radius is taken, not the best covered.
    """
    dx, dy = cols - cx, rows - cy
    dist = np.hypot(dx, dy)
    with np.errstate(invalid="ignore", divide="ignore"):
        radial = np.abs(dx * ux + dy * uy) >= np.cos(np.radians(25.0)) * dist
    d = dist[radial & (dist >= rmin - 1.0) & (dist <= rmax + 1.0)]
    if d.size == 0:
        return None
    edges_r = np.arange(np.floor(rmin) - 1.5, np.ceil(rmax) + 2.0)
    counts, _ = np.histogram(d, bins=edges_r)
    ring = np.convolve(counts, np.ones(3), mode="same")  # +/- 1 px
    centres = 0.5 * (edges_r[:-1] + edges_r[1:])
    coverage = ring / (2.0 * np.pi * np.maximum(centres, 1.0))
    is_peak = (ring >= np.roll(ring, 1)) & (ring >= np.roll(ring, -1))
    good = np.nonzero(is_peak & (coverage >= _MIN_COVERAGE) & (centres >= rmin))[0]
    if good.size == 0:
        return None
    k = good[-1]
    # the radius as the mean distance in the ring (sub-bin)
    near = np.abs(d - centres[k]) <= 1.5
    r = float(d[near].mean())
    return (cx, cy, r), float(ring[k])


def _thin_edges(mag, gx, gy):
    """Non-maximum suppression: pixels whose gradient magnitude peaks across the edge."""
    angle = np.mod(np.arctan2(gy, gx), np.pi)
    sector = np.rint(angle / (np.pi / 4)).astype(int) % 4  # 0: x, 1: diagonal, 2: y, 3: anti
    pad = np.pad(mag, 1, mode="edge")
    h, w = mag.shape
    keep = np.zeros_like(mag, dtype=bool)
    for s, (oy, ox) in enumerate(((0, 1), (1, 1), (1, 0), (1, -1))):
        fwd = pad[1 + oy:1 + oy + h, 1 + ox:1 + ox + w]
        back = pad[1 - oy:1 - oy + h, 1 - ox:1 - ox + w]
        keep |= (sector == s) & (mag >= fwd) & (mag > back)
    return keep & (mag > 0)


def _log_luminance(lum):
    """log of luminance with a floor 1 % of the median (at least 1e-3 of the 99th
    percentile), so a black background's noise does not become edges."""
    pos = np.maximum(lum, 0.0)
    floor = max(0.01 * float(np.median(pos)), 1e-3 * float(np.percentile(pos, 99)), 1e-12)
    return np.log(pos + floor)


def _block_mean(a, s):
    """(H, W) -> (ceil(H/s), ceil(W/s)) means over s x s blocks (edge blocks partial)."""
    if s == 1:
        return a
    h, w = a.shape
    hp, wp = -(-h // s) * s, -(-w // s) * s
    pad = np.pad(a, ((0, hp - h), (0, wp - w)), mode="edge")
    return pad.reshape(hp // s, s, wp // s, s).mean(axis=(1, 3))


def _n_rays(r):
    return int(np.clip(np.rint(2.0 * np.pi * r), 64, 4096))


def _outline_points(lum, cx, cy, r, band, outline=None):
    """Sub-pixel outline points (x, y) along rays from (cx, cy), within r +/- band,
    or within +/- band of a predicted `outline` ((M, 2) pixels around (cx, cy); an
    off-axis sphere's outline is an ellipse, up to a few pixels inside its circle).

    Along each ray the luminance is sampled every 0.25 px (bilinear) and
    differentiated with a 0.35 px Gaussian; the outline is the sub-sample peak of
    |derivative|. Rays leaving the image, with the peak at the band's end, or
    with a peak under a tenth of the median peak (no contrast there) are dropped.
    """
    h, w = lum.shape
    n = _n_rays(r)
    phi = 2.0 * np.pi * (np.arange(n) + 0.5) / n
    step = 0.25
    pad = 3.0
    offsets = np.arange(-band - pad, band + pad + step / 2, step)
    expected = np.full(n, r)
    if outline is not None:
        ox, oy = outline[:, 0] - cx, outline[:, 1] - cy
        expected = np.interp(phi, np.mod(np.arctan2(oy, ox), 2.0 * np.pi), np.hypot(ox, oy),
                             period=2.0 * np.pi)
    rho = expected[:, None] + offsets[None, :]
    cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
    xs, ys = cx + rho * cos, cy + rho * sin
    inside = ((xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)).all(axis=1)
    prof = ndimage.map_coordinates(lum, [ys.ravel(), xs.ravel()], order=1, mode="nearest")
    deriv = np.abs(
        ndimage.gaussian_filter1d(prof.reshape(xs.shape), _EDGE_SIGMA / step, axis=1, order=1)
    )
    core = np.abs(offsets) <= band
    lo, hi = np.nonzero(core)[0][[0, -1]]
    a = np.where(core[None, :], deriv, -np.inf)
    j = np.argmax(a, axis=1)
    ok = inside & (j > lo) & (j < hi)
    jj = np.clip(j, 1, len(offsets) - 2)
    y0, y1, y2 = (np.take_along_axis(deriv, (jj + k)[:, None], axis=1)[:, 0] for k in (-1, 0, 1))
    denom = y0 - 2.0 * y1 + y2
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.where(denom < 0.0, 0.5 * (y0 - y2) / denom, 0.0)
    edge = np.take_along_axis(rho, jj[:, None], axis=1)[:, 0] + np.clip(off, -0.5, 0.5) * step
    peak = y1
    if ok.any():
        ok &= peak >= 0.1 * np.median(peak[ok])
    return (cx + edge * cos[:, 0])[ok], (cy + edge * sin[:, 0])[ok]


def _robust_outline_fit(x, y, camera, n_rays, band):
    """Fit the outline to points (x, y) found within +/- band px, dropping points
    over 3 robust sigmas off; ValueError if too few are left or they scatter."""
    keep = np.ones(x.size, dtype=bool)
    for _ in range(5):
        if keep.sum() < 0.5 * n_rays:
            raise ValueError(
                "no sphere outline found along the circle: fewer than half its rays "
                "cross an edge (is the circle on the sphere?)"
            )
        circle, residual, outline = _fit_outline(x[keep], y[keep], camera)
        res = residual(x, y)
        sigma = 1.4826 * float(np.median(np.abs(res[keep])))
        new = np.abs(res) <= max(3.0 * sigma, 0.25)
        if np.array_equal(new, keep):
            break
        keep = new
    # Noise in the band gives points spread across it (sigma about 0.7 band); a real
    # outline's scatter was under 0.25 px on every Cycles probe photo.
    if sigma > max(0.3 * band, 0.5):
        raise ValueError(
            f"no sphere outline found along the circle: its edge points scatter by "
            f"{sigma:.1f} px (is the circle on the sphere?)"
        )
    return circle, outline


def _fit_outline(x, y, camera):
    """Circle (or tangent cone) through outline points (x, y).

    Returns (((cx, cy), r), residual, outline): the circle as `detect_sphere`
    returns it, residual(x, y) the points' distances off the fitted outline in
    pixels, and outline the fitted outline as (M, 2) pixels.
    """
    t = 2.0 * np.pi * np.arange(_OUTLINE_POINTS) / _OUTLINE_POINTS
    if camera is None or (isinstance(camera, str) and camera == "orthographic"):
        (cx, cy), r = _kasa_circle(x, y)
        outline = np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])
        return ((cx, cy), r), lambda u, v: np.hypot(u - cx, v - cy) - r, outline
    f, (px, py) = _check_camera(camera)
    d = _rays(x, y, f, px, py)
    w, *_ = np.linalg.lstsq(d, np.ones(len(d)), rcond=None)
    norm = np.linalg.norm(w)
    if not norm > 1.0:
        raise ValueError("the outline is not that of a sphere in front of the camera")
    axis, alpha = w / norm, np.arccos(1.0 / norm)

    def residual(u, v):
        return (np.arccos(np.clip(_rays(u, v, f, px, py) @ axis, -1.0, 1.0)) - alpha) * f

    circle = _major_axis_circle(axis, alpha, f, px, py)  # checks the cone is in front
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    ring = np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2
    gen = np.cos(alpha) * axis + np.sin(alpha) * ring  # the cone's generators
    outline = np.column_stack([px + f * gen[:, 0] / -gen[:, 2], py - f * gen[:, 1] / -gen[:, 2]])
    return circle, residual, outline


def _rays(x, y, f, px, py):
    """(N, 3) unit camera-space rays through pixels (x, y)."""
    d = np.stack([(x - px) / f, -(y - py) / f, -np.ones_like(x)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _finite_luminance(image, name):
    lum = _luminance(image)
    if lum.ndim != 2:
        raise ValueError(f"{name} must have shape (H, W) or (H, W, C>=3), got {lum.shape}")
    if not np.all(np.isfinite(lum)):
        raise ValueError(f"{name} has NaN or Inf pixels")
    return lum


def _background_luminance(background, lum):
    """Luminance (H, W) of a clean plate the shape of `lum`, or None for no plate."""
    if background is None:
        return None
    bg = _finite_luminance(background, "background")
    if bg.shape != lum.shape:
        raise ValueError(
            f"background must be the same view as the image, {lum.shape[1]}x{lum.shape[0]} "
            f"pixels, got {bg.shape[1]}x{bg.shape[0]}"
        )
    return bg


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


def _check_camera_kind(camera) -> None:
    if camera is None or (isinstance(camera, str) and camera == "orthographic"):
        return
    if not isinstance(camera, PerspectiveCamera):
        raise ValueError(
            f"camera must be None, 'orthographic' or a PerspectiveCamera, got {camera!r}"
        )
    _check_camera(camera)
