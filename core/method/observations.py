"""Observations: one lit photo plus its per-pixel geometry becomes flat BRDF samples.

For each pixel of a photo taken under one distant light of irradiance E (on a
surface facing the light), with world-space normal n, surface point P and
camera centre C:

    v = normalize(C - P),   rho = L / (E * (n . l))   (1/sr, per RGB channel)

and the sample's MERL cell is that of (l, v) in the local frame of n. Pixels
that cannot give a trustworthy rho are removed up front, each reason counted:
background (outside the mask, or no region), non-finite photo or geometry,
shadowed (visibility below a level), grazing light or view (n.l or n.v below a
cosine), and saturated (any channel at or above a clip level). The per-pixel
image-space curvature (``core.method.curvature``, in radians of normal turn per
``curvature_span_px`` pixels) rides along for the reliable-region stage,
computed on the full G-buffer so silhouettes are handled there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..brdf import merl
from . import curvature

REMOVAL_REASONS = ("background", "nonfinite", "shadowed", "grazing", "saturated")


@dataclasses.dataclass(frozen=True)
class ObservationSettings:
    """min_cosine: smallest n.l and n.v kept (0.1 = 84 degrees from the normal).
    shadow_level: visibility below this is shadowed. clip_level: a pixel with any
    channel >= this is saturated (None: no clipping; give the camera's white level).
    curvature_span_px: the unit of the per-sample curvature H is radians of normal
    turn per this many pixels (Vergne's image-space curvature, scaled): with 10,
    the paper's threshold 0.2 drops a pixel whose normal turns more than 0.02 rad
    (1.1 degrees) per pixel. The paper does not state its unit."""

    min_cosine: float = 0.1
    shadow_level: float = 0.5
    clip_level: float | None = None
    curvature_span_px: float = 10.0


@dataclasses.dataclass(frozen=True)
class Samples:
    """Flat BRDF samples (N of them); every array's first axis is N.

    n, l, v: (N, 3) unit vectors, world space (n normal, l to the light, v to the
    camera). rho: (N, 3) BRDF in 1/sr. radiance: (N, 3) the photo's linear value.
    irradiance: (N, 3) the light's irradiance for that photo.
    cells: (N, 3) int64 MERL bins of (l, v) about n. view: (N,) int photo index.
    pixel: (N, 2) int (row, column). region: (N,) int. curvature: (N,) mean
    curvature H (NaN where undefined). shapes: (H, W) of each view's image.
    removed: counts per reason in REMOVAL_REASONS (summed over views).
    """

    n: np.ndarray
    l: np.ndarray  # noqa: E741 - the paper's name
    v: np.ndarray
    rho: np.ndarray
    radiance: np.ndarray
    irradiance: np.ndarray
    cells: np.ndarray
    view: np.ndarray
    pixel: np.ndarray
    region: np.ndarray
    curvature: np.ndarray
    shapes: tuple = ()
    removed: dict = dataclasses.field(default_factory=dict)
    # (N, S, 3) world-space normals of the scan at S points spread over each
    # sample's pixel (NaN where a point misses the object); S = 0 (the default,
    # None): the pixel read at its centre (observe's footprint_normal)
    footprint: np.ndarray | None = None

    def __post_init__(self):
        if self.footprint is None:
            object.__setattr__(self, "footprint", np.zeros((len(self.rho), 0, 3)))

    def __len__(self) -> int:
        return len(self.rho)

    def subset(self, keep: np.ndarray) -> Samples:
        """The samples where ``keep`` (bool (N,) or indices) selects; counts kept."""
        index = np.asarray(keep)
        if index.dtype == bool and index.shape == (len(self),):
            index = np.flatnonzero(index)
        if index.dtype.kind in "iu":
            # np.take along the first axis: the rows fancy indexing gives (negative
            # indices wrap, out-of-range ones raise), several times faster on (N, 3).
            fields = {f: np.take(getattr(self, f), index, axis=0) for f in _ARRAY_FIELDS}
        else:  # anything else (an empty list, say): plain indexing
            fields = {f: getattr(self, f)[keep] for f in _ARRAY_FIELDS}
        return Samples(**fields, shapes=self.shapes, removed=dict(self.removed))

    def with_normals(self, index: np.ndarray, normals: np.ndarray) -> Samples:
        """Copy with new normals at ``index``; rho and cells recomputed there."""
        n = self.n.copy()
        n[index] = normals
        rho, cells = self.rho.copy(), self.cells.copy()
        cos_l = np.maximum(np.sum(normals * self.l[index], axis=1), 1e-12)[:, None]
        rho[index] = self.radiance[index] / (self.irradiance[index] * cos_l)
        cells[index] = merl.cells_about_normals(normals, self.l[index], self.v[index])
        return dataclasses.replace(self, n=n, rho=rho, cells=cells)


_ARRAY_FIELDS = tuple(f.name for f in dataclasses.fields(Samples)
                      if f.name not in ("shapes", "removed"))


def observe(
    photo: np.ndarray,
    normal: np.ndarray,
    position: np.ndarray,
    visibility: np.ndarray,
    region: np.ndarray,
    camera_center: np.ndarray,
    light: np.ndarray,
    irradiance=1.0,
    mask: np.ndarray | None = None,
    view_index: int = 0,
    settings: ObservationSettings | None = None,
    curvature_map: np.ndarray | None = None,
    saturated: np.ndarray | None = None,
    footprint_normal: np.ndarray | None = None,
) -> Samples:
    """Samples from one photo.

    photo: (H, W, 3) linear radiance. normal: (H, W, 3) world-space normals
    (zero or NaN on background). position: (H, W, 3) world-space points, scene
    units. visibility: (H, W) in [0, 1], fraction of the light reaching the
    point. region: (H, W) int, negative = background. camera_center: (3,)
    world space. light: (3,) world direction towards the light (normalised
    here). irradiance: scalar or RGB (3,), > 0. mask: optional (H, W) bool of
    pixels to use. curvature_map: (H, W) the result of :func:`image_curvature` for
    these G-buffers, to reuse it across photos taken from one camera (computed
    here when None). saturated: optional (H, W) bool of pixels at the camera's
    white level (``core.capture.photo_io.Photo.saturated``, found on the file's own code
    values); they are removed and counted as saturated, like pixels at or above
    ``settings.clip_level``. footprint_normal: optional (H, W, S, 3) world-space
    normals of the scan at S points spread over each pixel (NaN where a point
    misses the object), kept as ``Samples.footprint``: the refits then predict a
    pixel as the mean radiance over its area, as a camera's pixel records it.
    Raises ValueError for mismatched shapes or a bad light.
    """
    settings = settings or ObservationSettings()
    photo = np.asarray(photo, dtype=np.float64)
    shape = photo.shape[:2]
    if photo.shape != (*shape, 3):
        raise ValueError(f"photo must have shape (H, W, 3), got {photo.shape}")
    normal = np.asarray(normal, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    visibility = np.asarray(visibility, dtype=np.float64)
    region = np.asarray(region)
    for name, a, want in (("normal", normal, (*shape, 3)), ("position", position, (*shape, 3)),
                          ("visibility", visibility, shape), ("region", region, shape)):
        if a.shape != want:
            raise ValueError(f"{name} must have shape {want} to match the photo, got {a.shape}")
    light = np.asarray(light, dtype=np.float64)
    if light.shape != (3,) or not np.all(np.isfinite(light)) or np.linalg.norm(light) == 0:
        raise ValueError(f"light must be a finite, non-zero 3-vector, got {light}")
    light = light / np.linalg.norm(light)
    irradiance = np.broadcast_to(np.asarray(irradiance, dtype=np.float64), (3,))
    if not np.all(irradiance > 0) or not np.all(np.isfinite(irradiance)):
        raise ValueError(f"irradiance must be positive and finite, got {irradiance}")

    foreground = region >= 0
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != shape:
            raise ValueError(f"mask must have shape {shape}, got {mask.shape}")
        foreground &= mask
    # Per-pixel work goes in blocks of rows (_ROWS): its temporaries stay in cache
    # instead of being fresh image-sized arrays. Row gathers use np.take, several times
    # faster than fancy indexing of (H, W, 3) arrays, with the same values.
    normal_rows, position_rows = normal.reshape(-1, 3), position.reshape(-1, 3)
    photo_rows, visibility_flat = photo.reshape(-1, 3), visibility.reshape(-1)
    finite = np.empty(shape, dtype=bool)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite rows are dropped anyway
        for b in _blocks(finite.size):
            finite.reshape(-1)[b] = (
                _all_finite(normal_rows[b]) & _all_finite(position_rows[b])
                & np.isfinite(visibility_flat[b]) & (_norm(normal_rows[b]) > 0.5)
                & _all_finite(photo_rows[b]))
    if curvature_map is None:
        H = image_curvature(normal, position, foreground, settings)
    else:
        H = np.asarray(curvature_map, dtype=np.float64)
        if H.shape != shape:
            raise ValueError(f"curvature_map must have shape {shape}, got {H.shape}")

    keep = foreground.copy()
    removed = {"background": int(np.count_nonzero(~foreground))}
    stage = keep & ~finite
    removed["nonfinite"] = int(np.count_nonzero(stage))
    keep &= finite
    stage = keep & (visibility < settings.shadow_level)
    removed["shadowed"] = int(np.count_nonzero(stage))
    keep &= ~stage

    flat = np.flatnonzero(keep)  # row-major, as np.nonzero
    n = np.take(normal_rows, flat, axis=0)
    v = np.take(position_rows, flat, axis=0)
    camera_center = np.asarray(camera_center, dtype=np.float64)
    for b in _blocks(len(flat)):
        nb, vb = n[b], v[b]
        nb /= _norm(nb)[:, None]
        # render.view_directions, with the same rounding (tested equal)
        np.subtract(camera_center[None, :], vb, out=vb)
        length = _norm(vb)[:, None]
        np.divide(vb, length, out=vb, where=length > 0.0)
        vb[~(length[:, 0] > 0.0)] = 0.0  # a point at the camera centre
    cos_l = n @ light  # BLAS, over all rows at once as before (its rounding may depend on it)
    grazing = cos_l < settings.min_cosine
    for b in _blocks(len(flat)):
        grazing[b] |= _dot(n[b], v[b]) < settings.min_cosine
    removed["grazing"] = int(np.count_nonzero(grazing))
    saturated_rows = None
    if saturated is not None:
        saturated = np.asarray(saturated, dtype=bool)
        if saturated.shape != shape:
            raise ValueError(f"saturated must have shape {shape}, got {saturated.shape}")
        saturated_rows = np.take(saturated.reshape(-1), flat)
    if settings.clip_level is not None:
        clipped = np.any(np.take(photo_rows, flat, axis=0) >= settings.clip_level, axis=1)
        saturated_rows = clipped if saturated_rows is None else saturated_rows | clipped
    saturated = None if saturated_rows is None else saturated_rows & ~grazing
    removed["saturated"] = int(np.count_nonzero(saturated)) if saturated is not None else 0
    ok = ~grazing if saturated is None else ~grazing & ~saturated

    if not ok.all():
        sel = np.flatnonzero(ok)
        flat, n, v, cos_l = flat[sel], np.take(n, sel, axis=0), np.take(v, sel, axis=0), cos_l[sel]
    radiance = np.take(photo_rows, flat, axis=0)
    count = len(flat)
    l = np.empty((count, 3))  # noqa: E741
    l[:] = light
    rho = np.empty((count, 3))
    for b in _blocks(count):  # radiance / (irradiance cos_l)
        np.divide(radiance[b], np.multiply(irradiance[None, :], cos_l[b, None]), out=rho[b])
    cells = merl.cells_about_normals(n, light, v)
    pixel = np.empty((count, 2), dtype=np.int64)
    np.divmod(flat, shape[1], out=(pixel[:, 0], pixel[:, 1]))
    irr = np.empty((count, 3))
    irr[:] = irradiance
    footprint = None
    if footprint_normal is not None:
        footprint_normal = np.asarray(footprint_normal, dtype=np.float64)
        if footprint_normal.ndim != 4 or footprint_normal.shape[:2] != shape \
                or footprint_normal.shape[3] != 3 or footprint_normal.shape[2] < 1:
            raise ValueError(f"footprint_normal must have shape ({shape[0]}, {shape[1]}, S, 3)"
                             f", got {footprint_normal.shape}")
        footprint = np.take(footprint_normal.reshape(-1, *footprint_normal.shape[2:]), flat,
                            axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            footprint = footprint / np.linalg.norm(footprint, axis=2, keepdims=True)
    return Samples(
        n=n, l=l, v=v, rho=rho, radiance=radiance,
        irradiance=irr, cells=cells,
        view=np.full(count, view_index, dtype=np.int64),
        pixel=pixel,
        region=np.take(region.reshape(-1), flat).astype(np.int64, copy=False),
        curvature=np.take(H.reshape(-1), flat),
        shapes=(shape,),
        removed=removed,
        footprint=footprint,
    )


_ROWS = 16384  # rows per block of the per-pixel work in observe


def _blocks(count):
    """Slices of ``_ROWS`` consecutive rows covering ``count`` rows."""
    return (slice(start, start + _ROWS) for start in range(0, count, _ROWS))


def _all_finite(a):
    """(...) bool: every component of ``a`` (..., 3) is finite (np.all(isfinite, -1))."""
    f = np.isfinite(a)
    return f[..., 0] & f[..., 1] & f[..., 2]


def _norm(a):
    """(...) Euclidean length of ``a`` (..., 3), rounded as np.linalg.norm(a, axis=-1)
    (sum (x0^2 + x1^2) + x2^2, then sqrt), so results are bit for bit the same."""
    out = a[..., 0] * a[..., 0]
    square = a[..., 1] * a[..., 1]
    out += square
    out += np.multiply(a[..., 2], a[..., 2], out=square)
    return np.sqrt(out, out=out)


def _dot(a, b):
    """(...) dot products of rows of ``a`` and ``b`` (..., 3), rounded as
    np.sum(a * b, axis=-1): (a0 b0 + a1 b1) + a2 b2."""
    out = a[..., 0] * b[..., 0]
    product = a[..., 1] * b[..., 1]
    out += product
    out += np.multiply(a[..., 2], b[..., 2], out=product)
    return out


def image_curvature(normal, position, mask=None, settings: ObservationSettings | None = None):
    """(H, W) mean curvature of the G-buffers in radians of normal turn per
    ``settings.curvature_span_px`` pixels; NaN where undefined (background,
    non-finite geometry, silhouettes without a usable neighbour)."""
    settings = settings or ObservationSettings()
    normal = np.asarray(normal, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    ok = _all_finite(normal) & _all_finite(position)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    if not ok.all():  # (else the same arrays, without the copies)
        normal = np.where(ok[..., None], normal, np.nan)
        position = np.where(ok[..., None], position, np.nan)
    H, _ = curvature.mean_curvature(normal, position, mask=ok, length_scale="pixel")
    return H * settings.curvature_span_px


def group_index(labels: np.ndarray) -> tuple[np.ndarray, int]:
    """Rank of each label among the distinct labels, ascending, and their number:
    ``np.unique(labels, return_inverse=True)[1]`` and its length, for (N,) int
    labels (regions, views). Without a sort when the labels are small and
    non-negative (a count per value instead)."""
    labels = np.asarray(labels)
    if len(labels) and labels.min() >= 0 and labels.max() <= 4 * len(labels) + 1024:
        present = np.bincount(labels) > 0
        count = int(np.count_nonzero(present))
        if count == 1:
            return np.zeros(len(labels), dtype=np.intp), 1
        return (np.cumsum(present) - 1)[labels], count
    _, rank = np.unique(labels, return_inverse=True)
    return rank.reshape(-1), int(rank.max()) + 1 if len(rank) else 0


def concatenate(parts: list[Samples]) -> Samples:
    """One sample set from several photos (views keep the index each part carries)."""
    if not parts:
        raise ValueError("no observations to concatenate")
    points = {s.footprint.shape[1] for s in parts}
    if len(points) > 1:
        raise ValueError("every photo needs the same footprint points (or none), got "
                         f"{sorted(points)} per pixel")
    fields = {f: np.concatenate([getattr(s, f) for s in parts])
              for f in _ARRAY_FIELDS}
    shapes = tuple(sh for s in parts for sh in s.shapes)
    removed = {k: sum(s.removed.get(k, 0) for s in parts) for k in REMOVAL_REASONS}
    return Samples(**fields, shapes=shapes, removed=removed)
