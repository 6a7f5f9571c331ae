"""Per-pixel curvature of the visible surface from G-buffers (METHOD.md §3, Ono 2017 §3.1).

The paper drops pixels whose mean curvature ``H = (k_u + k_v) / 2`` exceeds a
threshold (0.2), because a multi-view reconstruction is blunted where the true
surface bends sharply, so normals there are wrong. Here H is measured on the
rendered normal and position passes of one camera.

Method. For every pixel the screen-space derivatives ``dP/du, dP/dv`` and
``dN/du, dN/dv`` (u = column, v = row) are taken by central differences, or
one-sided where one neighbour may not be used. On a surface ``dN = S dP`` with
S the shape operator, signed so that a convex surface with outward normals has
positive curvature (a sphere of radius R with ``N = (P - C) / R`` has
``S = I / R``). With ``J = [dP/du  dP/dv]`` and ``K = [dN/du  dN/dv]`` (3x2),
the matrix of S in the (u, v) coordinates is the least-squares solution
``M = (J^T J)^-1 J^T K`` (2x2), ``H = trace(M) / 2`` and the Gaussian curvature
is ``det(M)``. Both are invariants of S, so they do not depend on the camera:
orthographic and perspective renders give the same H, in 1 / scene unit. The
pixel footprint never enters, because the position pass carries it.

Units. ``H * length_scale`` is returned. With ``length_scale = 1`` (default) H
is in 1 / scene unit; with a length (e.g. the object's bounding radius) it is
dimensionless, relative to that length (a sphere of that radius gives 1);
with ``length_scale="pixel"`` H is multiplied by the local pixel footprint
(the smaller of the two per-axis footprints below, about the pixel's width
across the view ray at the surface's depth), which gives the image-space
curvature of Vergne et al. 2009: radians of normal turn per pixel. The
threshold of `curvature_mask` is in the same units as the returned H. The
paper does not state its units for 0.2. Note that relative to the bounding
radius every point of a convex object has H of about 1 or more, so 0.2 in
those units would reject nearly everything.

Which neighbours are used (a silhouette is not curvature, METHOD.md §3). A
surface sample is a pixel inside ``mask`` (if given) whose normal and position
are finite and whose normal has length >= 0.5 (the normal is then
renormalised; shorter normals are background or anti-aliased edge blends). The
link from pixel p to a direct neighbour q is used only when

- q is a surface sample inside the image,
- ``|P_q - P_p| <= discontinuity * footprint_p`` along the axis of the link, and
- the angle between ``N_p`` and ``N_q`` is at most ``max_normal_angle``.

``footprint_p`` is a robust local estimate, per image axis (u and v apart), of
the 3D step between neighbouring pixels, in scene units: first, per sample,
the shorter of its two steps along that axis to a neighbour sample; then the
median of that over the 3x3 window around p. The shorter step ignores a
depth jump on one side, the window median ignores a pixel whose every
neighbour is across a jump (a one-pixel object in front of a wall). Per axis,
because a slope seen at a grazing angle stretches the steps along one axis
only (a plane receding to the horizon): such steps are consistent with their
neighbours and are kept. A jump is therefore "more than ``discontinuity``
times the local step along that axis". A pixel needs a usable link in u and
in v (and the two tangents must not be parallel), else it gets H = NaN and
``valid = False``. NaN inputs only invalidate their own pixel: neighbours fall
back to one-sided differences.
"""

from __future__ import annotations

import numpy as np

# Normals shorter than this are background or pixels mostly covered by background.
_MIN_NORMAL_LENGTH = 0.5
# sin^2 of the smallest angle allowed between dP/du and dP/dv (about 0.6 degrees).
_MIN_SIN2_TANGENTS = 1e-4


def _check_inputs(normal, position, mask):
    n = np.asarray(normal)
    p = np.asarray(position)
    if n.ndim != 3 or n.shape[2] != 3:
        raise ValueError(f"normal must have shape (H, W, 3), got {n.shape}.")
    if p.shape != n.shape:
        raise ValueError(f"position must have the shape of normal {n.shape}, got {p.shape}.")
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != n.shape[:2]:
            raise ValueError(f"mask must have shape {n.shape[:2]}, got {m.shape}.")
        m = m.astype(bool)
    else:
        m = np.ones(n.shape[:2], dtype=bool)
    # no copies: curvatures() never writes into these
    return n.astype(np.float64, copy=False), p.astype(np.float64, copy=False), m


def _shift(a, dv, du, fill):
    """``out[i, j] = a[i + dv, j + du]``, ``fill`` outside the image."""
    h, w = a.shape[:2]
    out = np.full_like(a, fill)
    src_r = slice(max(dv, 0), h + min(dv, 0))
    dst_r = slice(max(-dv, 0), h + min(-dv, 0))
    src_c = slice(max(du, 0), w + min(du, 0))
    dst_c = slice(max(-du, 0), w + min(-du, 0))
    out[dst_r, dst_c] = a[src_r, src_c]
    return out


# A 9-input sorting network (Knuth's 25 comparators) pruned to what its five lowest
# outputs need, which is all a median of at most nine values reads: (i, j, min_only)
# puts min(s_i, s_j) in s_i and, unless min_only, max(s_i, s_j) in s_j. Checked on all
# 2^9 zero-one inputs in tests/core/method/test_curvature.py (0-1 principle).
_LOW5_OF_9 = ((0, 3, 0), (1, 7, 0), (2, 5, 0), (4, 8, 0), (0, 7, 0), (2, 4, 0), (3, 8, 0),
              (5, 6, 0), (0, 2, 0), (1, 3, 0), (4, 5, 0), (7, 8, 1), (1, 4, 0), (3, 6, 1),
              (5, 7, 1), (0, 1, 0), (2, 4, 0), (3, 5, 0), (2, 3, 0), (4, 5, 1), (1, 2, 0),
              (3, 4, 0))
_BAND = 16384  # pixels per band of window_nanmedian3: its nine planes stay in cache
_CURVATURE_BAND = 32768  # pixels per band of rows in curvatures


def _diff(a, dv, du):
    """``_shift(a, dv, du, 0.0) - a`` for a shift along one axis, without the
    shifted copy: the neighbour minus the pixel, ``0.0 - a`` where it is outside."""
    out = np.empty_like(a)
    if out.shape[0 if dv else 1] == 0:
        return out
    if dv == 0:
        inner, edge = (slice(None), slice(0, -1)), (slice(None), -1)
        nxt = (slice(None), slice(1, None))
        if du < 0:
            inner, edge, nxt = (slice(None), slice(1, None)), (slice(None), 0), inner
    else:
        inner, edge, nxt = slice(0, -1), -1, slice(1, None)
        if dv < 0:
            inner, edge, nxt = slice(1, None), 0, inner
    np.subtract(a[nxt], a[inner], out=out[inner])
    np.subtract(0.0, a[edge], out=out[edge])
    return out


def _mirror_norms(d_fwd, d_back, fwd_sq, axis):
    """``_dot(d_back, d_back)`` from ``fwd_sq = _dot(d_fwd, d_fwd)``, where d_back is
    the backward difference along ``axis`` (0 rows, 1 columns) and d_fwd the forward
    one: inside the image d_back is d_fwd of the previous pixel negated, exactly,
    and squares drop the sign, so only the first row or column is computed."""
    out = np.empty_like(fwd_sq)
    if axis == 1:
        out[:, 1:] = fwd_sq[:, :-1]
        out[:, :1] = _dot(d_back[:, :1], d_back[:, :1])
    else:
        out[1:] = fwd_sq[:-1]
        out[:1] = _dot(d_back[:1], d_back[:1])
    return out


def window_nanmedian3(a):
    """Median of the finite values of ``a`` (H, W) over each 3x3 window; NaN if none.

    With k finite values the median is the mean of the sorted values number
    (k - 1) // 2 and k // 2 (0-based), as ``np.nanmedian``. Computed with a
    sorting network on the nine shifted planes (NaN as +inf: last, uncounted), in
    bands of rows; the same values as a full sort of the 3x3 stack.
    """
    a = np.asarray(a)
    h, w = a.shape
    pad = np.full((h + 2, w + 2), np.inf, dtype=a.dtype)
    pad[1:-1, 1:-1] = a
    finite = np.isfinite(pad).view(np.uint8)
    np.copyto(pad, np.inf, where=np.isnan(pad))  # -inf sorts first, uncounted, as in a sort
    out = np.empty((h, w), dtype=np.result_type(a.dtype, 0.5))
    band = max(1, _BAND // max(w, 1))
    for r0 in range(0, h, band):
        r1 = min(r0 + band, h)
        s = [pad[r0 + dv:r1 + dv, du:du + w] for dv in (0, 1, 2) for du in (0, 1, 2)]
        f = finite[r0:r1 + 2]
        c = f[:, :-2] + f[:, 1:-1]
        c += f[:, 2:]
        count = c[:-2] + c[1:-1]
        count += c[2:]
        for i, j, min_only in _LOW5_OF_9:
            if min_only:
                s[i] = np.minimum(s[i], s[j])
            else:
                s[i], s[j] = np.minimum(s[i], s[j]), np.maximum(s[i], s[j])
        # sorted values number (count - 1) // 2 and count // 2: both 4 where count is 9
        lo, hi = s[4].copy(), s[4].copy()
        part = count < 9
        if part.any():
            low = [x[part] for x in s[:5]]
            lo[part] = np.choose((np.maximum(count[part], 1) - 1) >> 1, low)
            hi[part] = np.choose(count[part] >> 1, low)
        out[r0:r1] = np.where(count > 0, 0.5 * (lo + hi), np.nan)
    return out


def window_nanmedian3_at(a, rows, cols):
    """``window_nanmedian3(a)[rows, cols]`` at those pixels only (bit for bit).

    a: (H, W); rows, cols: (K,) int, inside the image. Returns (K,).
    """
    a = np.asarray(a)
    h, w = a.shape
    pad = np.full((h + 2, w + 2), np.nan, dtype=a.dtype)
    pad[1:-1, 1:-1] = a
    centre = (np.asarray(rows) + 1) * (w + 2) + (np.asarray(cols) + 1)
    offsets = np.array([dv * (w + 2) + du for dv in (-1, 0, 1) for du in (-1, 0, 1)])
    stack = pad.reshape(-1)[centre[:, None] + offsets]  # (K, 9)
    stack.sort(axis=1)  # NaN sorts last
    count = np.isfinite(stack).sum(axis=1)
    lo = np.take_along_axis(stack, (np.maximum(count - 1, 0) // 2)[:, None], axis=1)[:, 0]
    hi = np.take_along_axis(stack, (count // 2)[:, None], axis=1)[:, 0]
    return np.where(count > 0, 0.5 * (lo + hi), np.nan)


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def curvatures(
    normal: np.ndarray,
    position: np.ndarray,
    mask: np.ndarray | None = None,
    discontinuity: float = 4.0,
    length_scale: float | str = 1.0,
    max_normal_angle: float = np.pi / 3,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and Gaussian curvature of the visible surface, per pixel.

    normal: (H, W, 3), world space, unit, facing the camera; zero or NaN on
        background. Any float dtype.
    position: (H, W, 3), world space, scene units; the surface point seen by
        each pixel. Any float dtype.
    mask: optional (H, W) bool, True on the object. Pixels outside it are
        background even where the passes hold data.
    discontinuity: a neighbour farther (in 3D) than this many local steps along
        the same image axis is across a depth jump and is not used. Must be > 0.
    length_scale: positive length in scene units, or ``"pixel"``. H is
        returned times this length and K times its square (see module doc).
    max_normal_angle: radians; a neighbour whose normal differs by more is not
        used (a crease or an occlusion, not a bend).

    Returns ``(H, K, valid)``: H (H, W) float64, mean curvature
    ``(k1 + k2) / 2`` (convex with outward normals positive), in
    1 / scene unit times ``length_scale``; K (H, W) float64, Gaussian curvature
    ``k1 k2`` in 1 / scene unit^2 times ``length_scale^2``; both NaN where
    ``valid`` (H, W) bool is False. Principal curvatures are
    ``H +- sqrt(max(H^2 - K, 0))``.
    """
    return _curvatures(normal, position, mask, discontinuity, length_scale, max_normal_angle)


def _curvatures(normal, position, mask, discontinuity, length_scale, max_normal_angle,
                gaussian=True):
    """`curvatures`; with ``gaussian=False`` K is not computed (None)."""
    n, p, m = _check_inputs(normal, position, mask)
    if not (np.isscalar(discontinuity) and discontinuity > 0):
        raise ValueError(f"discontinuity must be a positive number, got {discontinuity!r}.")
    per_pixel = isinstance(length_scale, str)
    if per_pixel and length_scale != "pixel":
        raise ValueError(
            f'length_scale must be a positive length or "pixel", got {length_scale!r}.'
        )
    if not per_pixel and not (np.isfinite(length_scale) and length_scale > 0):
        raise ValueError(f"length_scale must be a positive length, got {length_scale!r}.")
    args = (discontinuity, per_pixel, length_scale, max_normal_angle, gaussian)
    h, w = m.shape
    rows = max(1, _CURVATURE_BAND // max(w, 1))
    if h <= rows + 4:
        return _curvature_band(n, p, m, *args)
    # Bands of rows, each with the two rows either side that its footprints read
    # (a footprint is the 3x3 median of the steps to the neighbours): the same
    # values as the whole image at once, with the temporaries in cache.
    mean, valid = np.empty((h, w)), np.empty((h, w), dtype=bool)
    gauss = np.empty((h, w)) if gaussian else None
    for r0 in range(0, h, rows):
        r1 = min(r0 + rows, h)
        lo, hi = max(r0 - 2, 0), min(r1 + 2, h)
        parts = _curvature_band(n[lo:hi], p[lo:hi], m[lo:hi], *args)
        for out, part in zip((mean, gauss, valid), parts, strict=True):
            if out is not None:
                out[r0:r1] = part[r0 - lo:r1 - lo]
    return mean, gauss, valid


def _curvature_band(n, p, m, discontinuity, per_pixel, length_scale, max_normal_angle,
                    gaussian):
    """The curvatures of the G-buffer rows given (their first and last rows lack
    their outer neighbours); arguments checked by the caller."""
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.sqrt(_dot(n, n))
        finite_p = np.isfinite(p)
        sample = m & np.isfinite(length) & finite_p[..., 0] & finite_p[..., 1] & finite_p[..., 2]
        sample &= length >= _MIN_NORMAL_LENGTH
    # Zero the non-samples so that no NaN or Inf enters any arithmetic below.
    if sample.all():  # the same values, without the selects
        n = n / length[..., None]
    else:
        n = np.where(sample[..., None], n / np.where(sample, length, 1.0)[..., None], 0.0)
        p = np.where(sample[..., None], p, 0.0)

    # Differences to the four direct neighbours: (dv, du) = right, left, down, up.
    offsets = ((0, 1), (0, -1), (1, 0), (-1, 0))
    dp = [_diff(p, dv, du) for dv, du in offsets]
    dn = [_diff(n, dv, du) for dv, du in offsets]
    q_s = [_shift(sample, dv, du, False) & sample for dv, du in offsets]
    dist, dn2 = [], []  # |dP| and |dN|^2 per link; left/up mirror right/down
    for k, axis in ((0, 1), (2, 0)):
        for d, out in ((dp, dist), (dn, dn2)):
            sq = _dot(d[k], d[k])
            out += [sq, _mirror_norms(d[k], d[k + 1], sq, axis)]
    dist = [np.sqrt(d) for d in dist]

    # Robust footprint per image axis: shorter step along it, then a 3x3 median
    # (module doc). Per axis, so that a slope stretched along v is not a jump.
    footprint = []
    for k in (0, 2):
        near = np.fmin(np.where(q_s[k], dist[k], np.nan), np.where(q_s[k + 1], dist[k + 1], np.nan))
        footprint += [window_nanmedian3(near)] * 2

    # For unit normals the angle test reads 1 - |N_q - N_p|^2 / 2 >= cos(max angle).
    max_dn2 = 2.0 * (1.0 - np.cos(max_normal_angle))
    with np.errstate(invalid="ignore"):  # NaN footprint compares False: no link
        link = [
            s & (d <= discontinuity * fp) & (e2 <= max_dn2)
            for s, d, e2, fp in zip(q_s, dist, dn2, footprint, strict=True)
        ]

    # Central differences where both neighbours along an axis are linked,
    # one-sided where one is: weights 1/2 and 1/2, or 1 and 0.
    w = [l * np.where(link[k ^ 1], 0.5, 1.0) for k, l in enumerate(link)]
    has_u = link[0] | link[1]
    has_v = link[2] | link[3]
    # pu = w0 dp0 - w1 dp1 and so on, in place (the differences are not used again)
    pu, pv, nu, nv = (
        np.subtract(np.multiply(w[a][..., None], d[a], out=d[a]),
                    np.multiply(w[a + 1][..., None], d[a + 1], out=d[a + 1]), out=d[a])
        for d, a in ((dp, 0), (dp, 2), (dn, 0), (dn, 2)))

    # M = (J^T J)^-1 J^T K with the closed-form 2x2 inverse.
    aa, ab, bb = _dot(pu, pu), _dot(pu, pv), _dot(pv, pv)
    det = aa * bb - ab * ab
    valid = sample & has_u & has_v & (det > _MIN_SIN2_TANGENTS * aa * bb) & (det > 0)
    inv_det = 1.0 / np.where(valid, det, 1.0)
    a_nu, a_nv, b_nu, b_nv = _dot(pu, nu), _dot(pu, nv), _dot(pv, nu), _dot(pv, nv)
    m11 = (bb * a_nu - ab * b_nu) * inv_det
    m22 = (aa * b_nv - ab * a_nv) * inv_det
    mean = 0.5 * (m11 + m22)

    # The less stretched axis approximates the footprint across the view ray.
    scale = np.fmin(footprint[0], footprint[2]) if per_pixel else float(length_scale)
    mean = np.where(valid, mean * scale, np.nan)
    if not gaussian:
        return mean, None, valid
    m12 = (bb * a_nv - ab * b_nv) * inv_det
    m21 = (aa * b_nu - ab * a_nu) * inv_det
    gauss = m11 * m22 - m12 * m21
    gauss = np.where(valid, gauss * scale**2, np.nan)
    return mean, gauss, valid


def mean_curvature(
    normal: np.ndarray,
    position: np.ndarray,
    mask: np.ndarray | None = None,
    discontinuity: float = 4.0,
    length_scale: float | str = 1.0,
    **kw,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean curvature H (H, W) float64 and ``valid`` (H, W) bool; see `curvatures`.

    H is in 1 / scene unit times ``length_scale`` (positive where convex with
    outward normals), NaN where ``valid`` is False.
    """
    kw = {"max_normal_angle": np.pi / 3, **kw}
    mean, _, valid = _curvatures(normal, position, mask, discontinuity, length_scale,
                                 gaussian=False, **kw)
    return mean, valid


def curvature_mask(
    normal: np.ndarray,
    position: np.ndarray,
    threshold: float = 0.2,
    mask: np.ndarray | None = None,
    **kw,
) -> np.ndarray:
    """Reliable-region filter of Ono 2017 §3.1: (H, W) bool, True where ``|H| <= threshold``.

    ``threshold`` is in the units of the returned H, i.e. 1 / scene unit times
    ``length_scale`` (keyword passed on to `curvatures` with the others).
    The magnitude is tested, not the signed H: a reconstruction blunts concave
    creases as it blunts convex edges, so strongly concave pixels (H < 0) are
    as unreliable as convex ones. Pixels where H is undefined (background,
    silhouettes, too few neighbours) are not reliable. Note that H misses
    saddles (k1 = -k2 gives H = 0), as in the paper.
    """
    if not (np.isscalar(threshold) and threshold >= 0):
        raise ValueError(f"threshold must be a non-negative number, got {threshold!r}.")
    mean, valid = mean_curvature(normal, position, mask, **kw)
    with np.errstate(invalid="ignore"):
        return valid & (np.abs(mean) <= threshold)
