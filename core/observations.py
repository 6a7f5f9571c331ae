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
image-space curvature (``core.curvature``, in radians of normal turn per
``curvature_span_px`` pixels) rides along for the reliable-region stage,
computed on the full G-buffer so silhouettes are handled there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import curvature, merl, render

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

    def __len__(self) -> int:
        return len(self.rho)

    def subset(self, keep: np.ndarray) -> Samples:
        """The samples where ``keep`` (bool (N,) or indices) selects; counts kept."""
        fields = {f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self)
                  if f.name not in ("shapes", "removed")}
        return Samples(**fields, shapes=self.shapes, removed=dict(self.removed))

    def with_normals(self, index: np.ndarray, normals: np.ndarray) -> Samples:
        """Copy with new normals at ``index``; rho and cells recomputed there."""
        n = self.n.copy()
        n[index] = normals
        rho, cells = self.rho.copy(), self.cells.copy()
        cos_l = np.maximum(np.sum(normals * self.l[index], axis=1), 1e-12)[:, None]
        rho[index] = self.radiance[index] / (self.irradiance[index] * cos_l)
        cells[index] = merl.cells_from_dirs(merl.to_local(normals, self.l[index]),
                                            merl.to_local(normals, self.v[index]))
        return dataclasses.replace(self, n=n, rho=rho, cells=cells)


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
    here when None). Raises ValueError for mismatched shapes or a bad light.
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
    geometry_ok = (np.all(np.isfinite(normal), axis=-1) & np.all(np.isfinite(position), axis=-1)
                   & np.isfinite(visibility) & (np.linalg.norm(np.nan_to_num(normal), axis=-1)
                                                > 0.5))
    finite = geometry_ok & np.all(np.isfinite(photo), axis=-1)
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

    rows, cols = np.nonzero(keep)
    n = normal[rows, cols]
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    p = position[rows, cols]
    v = render.view_directions(camera_center, p)
    cos_l = n @ light
    cos_v = np.sum(n * v, axis=1)
    grazing = (cos_l < settings.min_cosine) | (cos_v < settings.min_cosine)
    removed["grazing"] = int(np.count_nonzero(grazing))
    radiance = photo[rows, cols]
    saturated = np.zeros(len(rows), dtype=bool)
    if settings.clip_level is not None:
        saturated = np.any(radiance >= settings.clip_level, axis=1) & ~grazing
    removed["saturated"] = int(np.count_nonzero(saturated))
    ok = ~grazing & ~saturated

    n, v, radiance, cos_l = n[ok], v[ok], radiance[ok], cos_l[ok]
    rows, cols = rows[ok], cols[ok]
    l = np.broadcast_to(light, n.shape).copy()  # noqa: E741
    rho = radiance / (irradiance[None, :] * cos_l[:, None])
    cells = merl.cells_from_dirs(merl.to_local(n, l), merl.to_local(n, v))
    return Samples(
        n=n, l=l, v=v, rho=rho, radiance=radiance,
        irradiance=np.broadcast_to(irradiance, rho.shape).copy(), cells=cells,
        view=np.full(len(rows), view_index, dtype=np.int64),
        pixel=np.stack([rows, cols], axis=1).astype(np.int64),
        region=region[rows, cols].astype(np.int64),
        curvature=H[rows, cols],
        shapes=(shape,),
        removed=removed,
    )


def image_curvature(normal, position, mask=None, settings: ObservationSettings | None = None):
    """(H, W) mean curvature of the G-buffers in radians of normal turn per
    ``settings.curvature_span_px`` pixels; NaN where undefined (background,
    non-finite geometry, silhouettes without a usable neighbour)."""
    settings = settings or ObservationSettings()
    normal = np.asarray(normal, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    ok = np.all(np.isfinite(normal), axis=-1) & np.all(np.isfinite(position), axis=-1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    H, _ = curvature.mean_curvature(np.where(ok[..., None], normal, np.nan),
                                    np.where(ok[..., None], position, np.nan),
                                    mask=ok, length_scale="pixel")
    return H * settings.curvature_span_px


def concatenate(parts: list[Samples]) -> Samples:
    """One sample set from several photos (views keep the index each part carries)."""
    if not parts:
        raise ValueError("no observations to concatenate")
    fields = {f.name: np.concatenate([getattr(s, f.name) for s in parts])
              for f in dataclasses.fields(Samples) if f.name not in ("shapes", "removed")}
    shapes = tuple(sh for s in parts for sh in s.shapes)
    removed = {k: sum(s.removed.get(k, 0) for s in parts) for k in REMOVAL_REASONS}
    return Samples(**fields, shapes=shapes, removed=removed)
