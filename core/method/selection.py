"""The paper's selection step: render each candidate BRDF, keep the closest by KL.

Ono et al. (2017, Sec. 3.2; METHOD.md §6) reconstruct the BRDF several times
from random subsets of the reliable region, render every reconstruction with
the reconstructed shape from the photo viewpoints under the same distant
light, and keep the one whose intensity distribution has the smallest KL
divergence to the photos'.

This is the fast path of that step: rendering is direct lighting from
G-buffers in numpy (no Cycles, no interreflection), so it is a pure function of
arrays. The G-buffers of one photo (normal, position, visibility, mask, all
(H, W, ...) in world space) come from the reconstructed shape seen by that
photo's camera; they are held, with the photo and its light, in a :class:`View`.

Aggregation over views: the score of a candidate is the *mean* of its per-view
KL divergences (``aggregate="mean"``, default), so scores keep their scale
whatever the number of photos; ``aggregate="sum"`` is offered and picks the
same winner. Each view's KL is taken over the pixels inside that view's mask
whose photo value is finite (NaN/Inf photo pixels are excluded and counted).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..brdf import merl, render
from .kl import kl_divergence

AGGREGATES = ("mean", "sum")


@dataclass(frozen=True, eq=False)
class View:
    """One photo under one distant light, with the G-buffers of the reconstructed shape.

    Attributes
    ----------
    photo : (H, W, 3) float
        Linear radiance (decoded from sRGB at the edge, if it ever was); NaN or
        Inf marks pixels to ignore (saturated, missing).
    normal : (H, W, 3) float
        Surface normals, world space; renormalised where the mask is set.
    visibility : (H, W) float in [0, 1]
        Fraction of the light reaching each point (0 = cast shadow).
    mask : (H, W) bool
        Pixels covered by the object.
    position : (H, W, 3) float
        Surface points, world space (same length unit as ``camera_center``).
    camera_center : (3,) float
        Camera centre, world space.
    light : (3,) float
        Direction towards the distant light, world space (normalised here).
    irradiance : float or (3,) float
        Irradiance of the light on a surface facing it, W/m^2 (RGB or grey).
    """

    photo: np.ndarray
    normal: np.ndarray
    visibility: np.ndarray
    mask: np.ndarray
    position: np.ndarray
    camera_center: np.ndarray
    light: np.ndarray
    irradiance: float | np.ndarray = 1.0


@dataclass(frozen=True, eq=False)
class SelectionResult:
    """Outcome of :func:`select_by_kl`.

    Attributes
    ----------
    kl : (T,) float64
        Score of each candidate table (mean or sum over views of the KL, nats).
    kl_per_view : (T, V) float64
        KL divergence of each candidate in each view, nats.
    winner : int
        Index of the smallest score (first one on a tie).
    excluded : (V,) int64
        Photo pixels inside each view's mask dropped because they were NaN/Inf.
    n_pixels : (V,) int64
        Pixels of each view that entered the histograms.
    renders : tuple of tuples of (H, W, 3) float64, or None
        ``renders[t][v]``: the render of candidate t in view v, when asked for.
    rmse : (T,) float64
        Each candidate's renders against the photos, over every view's usable
        pixels and the three channels: ``sqrt(sum (render - photo)^2 / sum
        photo^2)`` (relative RMSE; NaN where the photos are all 0). Not part of
        the KL choice; :func:`photo_eligible` reads it.
    """

    kl: np.ndarray
    kl_per_view: np.ndarray
    winner: int
    excluded: np.ndarray
    n_pixels: np.ndarray
    renders: tuple | None = None
    rmse: np.ndarray | None = None


def shade_gbuffer(
    table: np.ndarray,
    normal: np.ndarray,
    visibility: np.ndarray,
    mask: np.ndarray,
    position: np.ndarray,
    camera_center: np.ndarray,
    light: np.ndarray,
    irradiance=1.0,
    interpolation: str = "nearest",
) -> np.ndarray:
    """Direct-light radiance image of a G-buffer with a tabulated BRDF.

    ``L = rho(n, l, v) * max(n.l, 0) * E * visibility`` with
    ``v = normalize(camera_center - position)``; zero outside ``mask``. Only
    masked pixels with visibility > 0 and n.l > 0 are evaluated.

    Parameters
    ----------
    table : (3, 90, 90, 180) float
        BRDF in 1/sr (NaN = unmeasured, filled from the nearest measured cell).
    normal : (H, W, 3) float
        Normals, world space; renormalised (zero-length normals render black).
    visibility : (H, W) float in [0, 1]
        Light visibility (shadowing) per pixel.
    mask : (H, W) bool
        Pixels to shade.
    position : (H, W, 3) float
        Surface points, world space.
    camera_center : (3,) float
        Camera centre, world space.
    light : (3,) float
        Direction towards the distant light, world space; normalised here.
    irradiance : float or (3,) float
        W/m^2 on a surface facing the light.
    interpolation : {"nearest", "trilinear"}
        Table lookup, as in :func:`merl.evaluate`.

    Returns
    -------
    (H, W, 3) float64
        Radiance, W/(m^2 sr), finite and >= 0.
    """
    g = _LitPixels.of(normal, visibility, mask, position, camera_center, light, irradiance)
    image = np.zeros(g.shape)
    if len(g.rows):
        radiance = render.shade(table, g.n, g.light, g.v, g.irradiance, interpolation)
        radiance *= g.visibility[:, None]
        image[g.rows, g.cols] = radiance
    return image


def select_by_kl(
    tables: Sequence[np.ndarray],
    views: Sequence,
    n_bins: int = 64,
    floor: float = 1e-6,
    mode: str = "luminance",
    aggregate: str = "mean",
    keep_renders: bool = False,
    interpolation: str = "nearest",
) -> SelectionResult:
    """Pick the candidate BRDF whose renders best match the photos (paper Sec. 3.2).

    Parameters
    ----------
    tables : sequence of (3, 90, 90, 180) float, or of ``reconstruct.Reconstruction``
        Candidate BRDFs (T >= 1), 1/sr. A reconstruction is read only at the
        cells the views need (nearest interpolation); its table is not expanded.
    views : sequence of :class:`View`, or of mappings with the same keys
        The photos (V >= 1) with their G-buffers, light and irradiance.
    n_bins, floor, mode
        Passed to :func:`kl.kl_divergence`; the log-spaced bins span the
        positive range of each view's photo, down to ``DYNAMIC_RANGE`` of its
        brightest value (:func:`photo_range`), and are shared by all candidates.
    aggregate : {"mean", "sum"}
        How the per-view KLs make one score per candidate.
    keep_renders : bool
        Keep every render in the result (T x V images).
    interpolation : {"nearest", "trilinear"}
        Table lookup.

    Returns
    -------
    SelectionResult

    Raises
    ------
    ValueError
        No tables or views, a wrong shape, a view with no usable pixel, or a
        bad parameter.
    """
    tables = list(tables)
    views = [_as_view(v, i) for i, v in enumerate(views)]
    if not tables:
        raise ValueError("tables is empty: no candidate BRDF to choose from")
    if not views:
        raise ValueError("views is empty: no photo to compare the candidates with")
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")

    keep, excluded, photo_pixels = [], [], []
    for i, view in enumerate(views):
        photo = np.asarray(view.photo, dtype=np.float64)
        mask = np.asarray(view.mask)
        if mask.dtype != bool:
            raise ValueError(f"views[{i}].mask must be a bool array, got dtype {mask.dtype}")
        if photo.shape != (*mask.shape, 3):
            raise ValueError(
                f"views[{i}].photo must have shape {(*mask.shape, 3)} to match its mask, "
                f"got {photo.shape}"
            )
        finite = np.all(np.isfinite(photo), axis=-1)
        use = mask & finite
        if not use.any():
            raise ValueError(
                f"views[{i}] has no usable pixel: its mask is empty or every photo "
                "pixel inside it is NaN/Inf"
            )
        keep.append(use)
        excluded.append(int(np.count_nonzero(mask & ~finite)))
        photo_pixels.append(photo[use])

    # One set of bins per view, from the photo, shared by every candidate: the KLs of
    # different candidates are then comparable (render values outside the photo's
    # range fall into the end bins).
    bins = [photo_range(p) for p in photo_pixels]
    kl = np.zeros((len(tables), len(views)))
    misfit = np.zeros(len(tables))  # sum of squared differences to the photos
    photo_energy = float(sum(np.sum(p**2) for p in photo_pixels))
    renders = [] if keep_renders else None
    # The directions and cells of each view's pixels are the same for every candidate:
    # looked up once (nearest cells), each candidate is then read at those cells only.
    lookups = ([_ViewLookup.of(view) for view in views] if interpolation == "nearest"
               else None)
    for t, table in enumerate(tables):
        if lookups is not None and hasattr(table, "rho_at"):
            source = table.rho_at  # a Reconstruction: no full table needed
        else:
            table = np.asarray(getattr(table, "table", table), dtype=np.float64)
            if table.shape != (3, *merl.SHAPE):
                raise ValueError(
                    f"tables[{t}] must have shape (3, 90, 90, 180), got {table.shape}"
                )
            if np.isnan(table).any():  # fill once here, not once per view
                table = merl.fill_unmeasured(table)
            source = _TableSource(table.reshape(3, -1))
        row = []
        for v, view in enumerate(views):
            if lookups is not None:
                image = lookups[v].render(source)
            else:
                image = shade_gbuffer(
                    table, view.normal, view.visibility, view.mask, view.position,
                    view.camera_center, view.light, view.irradiance, interpolation,
                )
            rendered = image[keep[v]]
            kl[t, v] = kl_divergence(
                photo_pixels[v], rendered, n_bins=n_bins, floor=floor, mode=mode,
                range=bins[v],
            )
            misfit[t] += float(np.sum((rendered - photo_pixels[v]) ** 2))
            if keep_renders:
                row.append(image)
        if keep_renders:
            renders.append(tuple(row))

    score = kl.mean(axis=1) if aggregate == "mean" else kl.sum(axis=1)
    return SelectionResult(
        kl=score,
        kl_per_view=kl,
        winner=int(np.argmin(score)),
        excluded=np.asarray(excluded, dtype=np.int64),
        n_pixels=np.asarray([len(p) for p in photo_pixels], dtype=np.int64),
        renders=tuple(renders) if keep_renders else None,
        rmse=(np.sqrt(misfit / photo_energy) if photo_energy > 0.0
              else np.full(len(tables), np.nan)),
    )


# A candidate whose renders miss the photos by more than this many times the best
# candidate's relative RMSE is not chosen, whatever its KL: the KL compares intensity
# histograms, and a narrow spike far above anything photographed moves few pixels
# between bins. Measured (docs/results.md, "A trial far off the photos",
# bench/photo_check_bench.py): over 304 Balanced runs it moved the choice twice, both
# on the degraded bunny with its photos misregistered by half a pixel (sphere error
# 2.01 -> 0.58 and 3.59 -> 0.79), and changed no other run; factors 2 and 3 also
# moved exact Spot's polished aluminium, for the worse (0.143 -> 0.150).
MAX_RMSE_RATIO = 5.0


def photo_eligible(rmse, ratio: float = MAX_RMSE_RATIO) -> np.ndarray:
    """(T,) bool: the candidates whose relative RMSE against the photos (``rmse`` (T,),
    :attr:`SelectionResult.rmse`) is at most ``ratio`` times the smallest finite one;
    NaN counts as eligible (nothing to judge it by), Inf not; all of them where no
    RMSE is finite."""
    rmse = np.asarray(rmse, dtype=np.float64)
    finite = np.isfinite(rmse)
    if not finite.any():
        return np.ones(len(rmse), dtype=bool)
    return np.isnan(rmse) | (rmse <= ratio * np.min(rmse[finite]))


def eligible_winner(score, eligible) -> int:
    """Index of the smallest ``score`` (T,) among the ``eligible`` (T,) bool candidates
    (the first on a tie); of all of them where none is eligible."""
    score = np.asarray(score, dtype=np.float64)
    eligible = np.asarray(eligible, dtype=bool)
    if not eligible.any():
        return int(np.argmin(score))
    return int(np.flatnonzero(eligible)[np.argmin(score[eligible])])


# ----------------------------------------------------------------------------- helpers
@dataclass(frozen=True)
class _TableSource:
    """A full table read at flat cell indices: ``source(index) -> rho (N, 3)``."""

    flat: np.ndarray  # (3, 1458000)

    def __call__(self, index: np.ndarray) -> np.ndarray:
        return self.flat[:, index].T


@dataclass(frozen=True)
class _LitPixels:
    """The pixels of a G-buffer that :func:`shade_gbuffer` shades (in the mask, lit,
    light visible): (P,) image ``rows``, ``cols``, unit normals ``n`` and view
    directions ``v`` (P, 3), ``visibility`` (P,); the unit ``light``, the
    ``irradiance`` and the image ``shape`` (H, W, 3)."""

    shape: tuple
    rows: np.ndarray
    cols: np.ndarray
    n: np.ndarray
    v: np.ndarray
    visibility: np.ndarray
    light: np.ndarray
    irradiance: np.ndarray

    @classmethod
    def of(cls, normal, visibility, mask, position, camera_center, light,
           irradiance) -> _LitPixels:
        normal, visibility, mask, position, camera_center, light, irradiance = (
            _check_gbuffer(normal, visibility, mask, position, camera_center, light,
                           irradiance))
        n = normal[mask]
        n_len = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, n_len, out=np.zeros_like(n), where=n_len > 0.0)
        lit = (n @ light > 0.0) & (visibility[mask] > 0.0)
        rows, cols = np.nonzero(mask)
        return cls(shape=(*mask.shape, 3), rows=rows[lit], cols=cols[lit], n=n[lit],
                   v=render.view_directions(camera_center, position[mask][lit]),
                   visibility=visibility[mask][lit], light=light, irradiance=irradiance)


@dataclass(frozen=True)
class _ViewLookup:
    """A view's lit pixels (:class:`_LitPixels`) with their nearest cells and their
    ``cos`` = n.l, looked up once; ``render(source)`` shades a candidate given as
    ``source(flat cell indices) -> rho (N, 3)``: the image :func:`shade_gbuffer`
    gives, to the last bit."""

    pixels: _LitPixels
    index: np.ndarray
    above: np.ndarray
    cos: np.ndarray

    @classmethod
    def of(cls, view: View) -> _ViewLookup:
        g = _LitPixels.of(view.normal, view.visibility, view.mask, view.position,
                          view.camera_center, view.light, view.irradiance)
        l = np.broadcast_to(g.light, g.n.shape)  # noqa: E741 - the paper's name
        index, above = merl.lookup(g.n, l, g.v)
        return cls(pixels=g, index=index, above=above,
                   cos=np.clip(np.sum(g.n * l, axis=1), 0.0, None))

    def render(self, source) -> np.ndarray:
        g = self.pixels
        image = np.zeros(g.shape)
        if len(self.index):
            rho = merl.lookup_values(source(self.index), self.above)
            radiance = rho * self.cos[:, None] * g.irradiance
            radiance *= g.visibility[:, None]
            image[g.rows, g.cols] = radiance
        return image


#: The darkest photo value the bins resolve, as a fraction of the brightest: 20
#: stops, about what a bracketed HDR merge records (a single 16-bit linear frame
#: records 16). Darker values, and zeros, share the first bin. Without the bound a
#: synthetic photo whose shadows reach 1e-301 spread 64 bins over 301 decades, and a
#: 2e-7 relative change of the photo moved a trial's KL from 3.93 to 3.86 and
#: flipped the winner (docs/results.md, "Why one trial flipped").
DYNAMIC_RANGE = 1e-6


def photo_range(pixels: np.ndarray):
    """(lo, hi) the KL's log bins span for one photo, or None if no value is positive.

    pixels: (N, 3) or (N,) linear photo values (all channels count). hi is the
    brightest positive value; lo the darkest positive one, but not below
    ``DYNAMIC_RANGE * hi``. A single value is widened by e^(1/2) each way.
    """
    positive = pixels[pixels > 0.0]
    if positive.size == 0:
        return None
    hi = float(positive.max())
    lo = max(float(positive.min()), DYNAMIC_RANGE * hi)
    return (lo, hi) if hi > lo else (lo * np.exp(-0.5), hi * np.exp(0.5))



_VIEW_FIELDS = (
    "photo", "normal", "visibility", "mask", "position", "camera_center", "light",
)


def _as_view(view, i: int) -> View:
    """A :class:`View` from a View, a mapping, or any object with the same attributes."""
    if isinstance(view, View):
        return view
    if isinstance(view, Mapping):
        missing = [k for k in _VIEW_FIELDS if k not in view]
        if missing:
            raise ValueError(f"views[{i}] lacks {', '.join(missing)}")
        return View(**{k: view[k] for k in _VIEW_FIELDS}, irradiance=view.get("irradiance", 1.0))
    missing = [k for k in _VIEW_FIELDS if not hasattr(view, k)]
    if missing:
        raise ValueError(f"views[{i}] lacks {', '.join(missing)}")
    return View(
        **{k: getattr(view, k) for k in _VIEW_FIELDS},
        irradiance=getattr(view, "irradiance", 1.0),
    )


def _check_gbuffer(normal, visibility, mask, position, camera_center, light, irradiance):
    """Validate and convert the G-buffer arguments of :func:`shade_gbuffer`."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must have shape (H, W), got {mask.shape}")
    if mask.dtype != bool:
        raise ValueError(f"mask must be a bool array, got dtype {mask.dtype}")
    hw = mask.shape
    normal = np.asarray(normal, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    visibility = np.asarray(visibility, dtype=np.float64)
    for name, a, shape in (
        ("normal", normal, (*hw, 3)),
        ("position", position, (*hw, 3)),
        ("visibility", visibility, hw),
    ):
        if a.shape != shape:
            raise ValueError(f"{name} must have shape {shape} to match mask, got {a.shape}")
        if not np.all(np.isfinite(a[mask])):
            raise ValueError(f"{name} holds NaN or Inf inside the mask")
    vis = visibility[mask]
    if vis.size and (vis.min() < 0.0 or vis.max() > 1.0):
        raise ValueError("visibility must lie in [0, 1] inside the mask")
    camera_center = np.asarray(camera_center, dtype=np.float64)
    if camera_center.shape != (3,) or not np.all(np.isfinite(camera_center)):
        raise ValueError(f"camera_center must be a finite (3,) point, got {camera_center!r}")
    light = np.asarray(light, dtype=np.float64)
    length = np.linalg.norm(light) if light.shape == (3,) else 0.0
    if not (np.isfinite(length) and length > 0.0):
        raise ValueError(f"light must be a finite, non-zero (3,) direction, got {light!r}")
    irradiance = np.asarray(irradiance, dtype=np.float64)
    if irradiance.shape not in ((), (3,)):
        raise ValueError(f"irradiance must be a scalar or RGB (3,), got shape {irradiance.shape}")
    if not np.all(np.isfinite(irradiance)) or np.any(irradiance < 0.0):
        raise ValueError(f"irradiance must be finite and >= 0, got {irradiance!r}")
    return normal, visibility, mask, position, camera_center, light / length, irradiance
