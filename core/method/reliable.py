"""Reliable-region extraction (Ono et al. 2017, Sec. 3.1) and the random-subset trials.

Photogrammetry meshes are blunted, so normals are wrong where curvature is high,
and a sample with a wrong normal lands in the wrong MERL cell. Three
assumptions keep the trustworthy samples, each stage switchable and counted:

1. **Brightest peak (Eq. 2).** The brightest sample of each region is taken as
   the specular peak: its normal is set to h = normalize(l + v), so it lands in
   theta_h = 0. One pixel is fragile (noise, a hot pixel), so a sample's
   brightness is the *median* luminance of its 3 x 3 neighbourhood in its photo:
   a lone hot pixel has dim neighbours and cannot win. The corrected sample is
   exempt from the later stages (its normal is now set by assumption). Not
   applied where the brightest sample's normal is far from h (see
   ``ReliableSettings.peak_max_angle``): that maximum is not a specular peak.
2. **Curvature.** Samples whose |H| exceeds a threshold (radians of normal turn
   per 10 pixels, see ``core.method.observations``), or whose H is undefined, go.
3. **Monotonicity (Eq. 1, after Higo et al. 2010).** Within a region,
   reflectance should not decrease as n.h grows. Per region and channel, an
   isotonic (non-decreasing) fit of ln(rho) against n.h is made and samples
   further than a factor (1 + tolerance) from it in any channel go.
   It works on rho, not on radiance, so the cosine falloff is divided out: a
   Lambertian region has constant rho and is a flat isotonic fit, which its
   samples match to within their noise, so diffuse-dominated regions are not
   gutted (tested). What it removes are samples that are too bright or too dark
   for their n.h, the signature of a wrong normal. Skipped in a region where it
   would remove most samples (``monotonicity_max_fraction``): there the
   reflectance itself is not monotone in n.h (sheen, retro-reflection).

``reliable_candidates`` runs the stages; ``trial_candidates`` then makes the
paper's several reconstructions from random subsets (Sec. 3.2), each from
optimal cells (``core.method.sampling``: Bayes risk or condition number), seeded.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.optimize import isotonic_regression

from ..brdf import merl
from ..brdf.basis import Basis
from . import reconstruct, sampling
from .curvature import window_nanmedian3, window_nanmedian3_at
from .observations import Samples, group_index

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709


@dataclasses.dataclass(frozen=True)
class ReliableSettings:
    """Switches and thresholds of the reliable region (names as in the job file).

    ``peak_max_angle`` (radians) and ``monotonicity_max_fraction`` test the
    paper's assumptions against the data before applying them, per region:

    - Eq. (2) is applied only if the brightest sample's scanned normal is within
      ``peak_max_angle`` of h. Blunting bends normals by degrees to tens of
      degrees; a brightest sample 50 deg or more from h is not a specular peak
      (a Lambertian maximum sits at n = l, a sheen maximum at grazing), and
      setting its normal to h would plant a wrong sample at theta_h = 0.
    - Eq. (1) is applied only if it would remove at most
      ``monotonicity_max_fraction`` of the region's samples. A region whose
      reflectance falls as n.h grows (sheen, retro-reflection) breaks the
      assumption itself, and the stage would keep only a sliver of it.

    Skipped regions are listed in :class:`ReliableReport` ``skipped``.
    """

    use_curvature: bool = True
    curvature_threshold: float = 0.2
    use_monotonicity: bool = True
    monotonicity_tolerance: float = 1.0  # allowed factor (1 + tol) off the monotone fit
    monotonicity_max_fraction: float = 0.5
    use_brightest: bool = True
    peak_max_angle: float = float(np.radians(30.0))


@dataclasses.dataclass(frozen=True)
class ReliableReport:
    """Counts: ``input`` samples, samples ``removed`` per stage, ``peaks`` (indices
    into the returned candidates of the peak-corrected samples), ``kept``, and
    ``skipped``: per stage ("brightest", "monotonicity"), the region ids where
    the data rejected the stage's assumption, so it was not applied."""

    input: int
    removed: dict
    peaks: np.ndarray
    kept: int
    skipped: dict = dataclasses.field(default_factory=dict)


def brightness(samples: Samples) -> np.ndarray:
    """(N,) median luminance of each sample's 3 x 3 neighbourhood in its photo
    (only pixels that are samples count)."""
    lum = samples.radiance @ LUMINANCE
    score = np.empty(len(samples))
    for view in np.unique(samples.view):
        sel = np.flatnonzero(samples.view == view)
        image = np.full(samples.shapes[view], np.nan)
        r, c = samples.pixel[sel, 0], samples.pixel[sel, 1]
        image[r, c] = lum[sel]
        score[sel] = window_nanmedian3(image)[r, c]
    return score


def brightest_peaks(samples: Samples) -> np.ndarray:
    """Index of the brightest sample (by :func:`brightness`) of each region, the first
    among equals; (R,) int64, regions in ascending order.

    The 3 x 3 median is taken only where it can win. A median is at most its
    window's maximum; per region, ``T`` is the exact median at the samples of
    largest luminance, so the region's brightest sample reaches ``T``, and a sample
    whose window maximum is below ``T`` cannot be it. Only the samples whose
    window maximum is >= T (every winner among them) get their exact median.
    Same result as the arg-max of :func:`brightness` per region, which is used as
    is for inputs the bounds do not cover (non-finite or huge luminance, two
    samples on one pixel of a view, pixels or views outside ``shapes``).
    """

    lum = samples.radiance @ LUMINANCE
    count, view, pixel, region = len(samples), samples.view, samples.pixel, samples.region
    fast = (count > 0 and lum.min() >= -1e307 and lum.max() <= 1e307  # finite; 0.5 (lo + hi)
            and view.min() >= 0 and view.max() < len(samples.shapes))  # cannot overflow
    if fast:
        group, n_groups = group_index(region)  # rank of each sample's region
    upper = np.empty(count)  # maximum luminance over each sample's 3 x 3 window
    images = {}
    for v in np.flatnonzero(np.bincount(view, minlength=len(samples.shapes))) if fast else ():
        sel = np.flatnonzero(view == v)
        if sel[-1] - sel[0] + 1 == len(sel):  # one run of samples (as concatenate makes)
            sel = slice(sel[0], sel[-1] + 1)
        h, w = samples.shapes[v]
        r, c = pixel[sel, 0], pixel[sel, 1]
        if r.min() < 0 or r.max() >= h or c.min() < 0 or c.max() >= w:
            fast = False
            break
        at = r * w + c  # flat pixel index; + 2 r + w + 3 in the image padded by one pixel
        pad = np.full((h + 2, w + 2), -np.inf)  # the view's image, padded
        pad.reshape(-1)[at + 2 * r + (w + 3)] = lum[sel]
        inner = pad[1:-1, 1:-1]
        if np.count_nonzero(inner > -np.inf) != len(at):  # two samples on one pixel
            fast = False
            break
        rows = np.maximum(np.maximum(pad[:, :-2], pad[:, 1:-1]), pad[:, 2:])
        upper[sel] = np.take(np.maximum(np.maximum(rows[:-2], rows[1:-1]), rows[2:]), at)
        inner[inner == -np.inf] = np.nan  # missing pixels, for the median
        images[v] = inner
    if not fast:
        score = brightness(samples)
        peaks = []
        for value in np.unique(region):
            sel = np.flatnonzero(region == value)
            peaks.append(sel[np.argmax(score[sel])])
        return np.asarray(peaks, dtype=np.int64)

    def median_at(index):  # (K,) exact brightness of the samples ``index``
        out = np.empty(len(index))
        for v, image in images.items():
            part = np.flatnonzero(view[index] == v)
            out[part] = window_nanmedian3_at(image, pixel[index[part], 0], pixel[index[part], 1])
        return out

    def region_max(values, groups):  # (R,) maximum of ``values`` over each region
        if n_groups == 1:
            return np.array([values.max()])
        out = np.full(n_groups, -np.inf)
        np.maximum.at(out, groups, values)
        return out

    def spread(per_region, groups):  # per_region[groups]
        return per_region[0] if n_groups == 1 else per_region[groups]

    seeds = np.flatnonzero(lum == spread(region_max(lum, group), group))  # >= 1 per region
    bound = region_max(median_at(seeds), group[seeds])
    candidates = np.flatnonzero(upper >= spread(bound, group))
    score, groups = median_at(candidates), group[candidates]
    best = candidates[score == spread(region_max(score, groups), groups)]
    _, first = np.unique(group[best], return_index=True)
    return best[first].astype(np.int64)


@dataclasses.dataclass(frozen=True)
class _MonotoneInput:
    """The fields :func:`monotone_residuals` reads, gathered without copying the rest."""

    n: np.ndarray
    l: np.ndarray  # noqa: E741 - the paper's name
    v: np.ndarray
    rho: np.ndarray
    region: np.ndarray

    def __len__(self) -> int:
        return len(self.rho)

    @classmethod
    def take(cls, samples: Samples, index: np.ndarray) -> _MonotoneInput:
        return cls(*(np.take(getattr(samples, f), index, axis=0)
                     for f in ("n", "l", "v", "rho", "region")))


def monotone_residuals(samples: Samples) -> np.ndarray:
    """(N, 3) log-ratio ``|ln(rho / fit)|`` of each sample to its region's monotone fit.

    The fit is an isotonic (non-decreasing) regression of ``ln(rho + delta)``
    against n.h, per region and channel. It is done in log space because rho
    spans orders of magnitude on glossy materials: a least-squares fit on linear
    rho is dragged up by a few highlight values and then flags hundreds of dim
    samples. delta = 1e-3 x the region's median rho keeps black samples finite.
    """

    if len(samples) == 0:
        return np.zeros_like(samples.rho)
    # n.h, rounded as np.linalg.norm and np.sum over axis 1 round them, (x0 + x1) + x2,
    # in blocks of rows (the temporaries stay in cache)
    ndoth = np.empty(len(samples))
    for start in range(0, len(samples), 16384):
        rows = slice(start, start + 16384)
        h, n, out = samples.l[rows] + samples.v[rows], samples.n[rows], ndoth[rows]
        norm = h[:, 0] * h[:, 0]
        square = h[:, 1] * h[:, 1]
        norm += square
        norm += np.multiply(h[:, 2], h[:, 2], out=square)
        h /= np.sqrt(norm, out=norm)[:, None]
        np.multiply(n[:, 0], h[:, 0], out=out)
        out += np.multiply(n[:, 1], h[:, 1], out=square)
        out += np.multiply(n[:, 2], h[:, 2], out=square)
    # The order of np.argsort(ndoth, kind="stable") within each region (ascending
    # region), by LSD radix sort (2.5x faster here): stable passes over the 16-bit
    # digits of a key that orders as the floats do (-0 ties +0, NaNs tie last),
    # lowest first, then one over the region.
    key = (ndoth + 0.0).view(np.uint64)  # + 0.0 turns -0.0 into +0.0
    if not ndoth.min() >= 0.0:  # else the bits of the floats already order as they do
        key = np.where(key >> np.uint64(63), ~key, key | np.uint64(1 << 63))
        key[np.isnan(ndoth)] = np.uint64(2**64 - 1)
    group, n_groups = group_index(samples.region)
    order = np.arange(len(samples))
    for shift in (0, 16, 32, 48):
        digit = (key >> np.uint64(shift)).astype(np.uint16)
        if digit.min() != digit.max():
            order = order[np.argsort(digit[order], kind="stable")]  # a radix sort
    if n_groups > 1:
        by_group = group[order]
        order = order[np.argsort(by_group.astype(np.uint16) if n_groups <= 2**16
                                 else by_group, kind="stable")]
    ends = np.cumsum(np.bincount(group, minlength=n_groups))
    rho_sorted = np.take(samples.rho, order, axis=0)
    res = np.empty((3, len(samples)))  # per channel, in that order
    for start, stop in zip(ends - np.bincount(group, minlength=n_groups), ends, strict=True):
        for c in range(3):
            rho = rho_sorted[start:stop, c]
            delta = 1e-3 * max(float(np.median(rho)), 1e-12)
            y = np.maximum(rho, 0.0)
            y += delta
            np.log(y, out=y)  # ln(max(rho, 0) + delta)
            fit = isotonic_regression(y, increasing=True).x
            np.abs(np.subtract(y, fit, out=fit), out=res[c, start:stop])
    where = np.empty_like(order)  # the inverse permutation: a gather beats a scatter
    where[order] = np.arange(len(order))
    out = np.empty_like(samples.rho)
    for c in range(3):
        out[:, c] = np.take(res[c], where)
    return out


def reliable_candidates(
    samples: Samples,
    settings: ReliableSettings | None = None,
    rng: np.random.Generator | int | None = None,
) -> tuple[Samples, ReliableReport]:
    """Run the reliable-region stages on all samples of all photos.

    Returns the candidates (a :class:`Samples` subset, peak normals corrected)
    and a :class:`ReliableReport`. ``rng`` is accepted for a uniform pipeline
    signature; the stages are deterministic. Raises ValueError when no sample
    is left, naming the stage that removed the last ones.
    """
    del rng  # deterministic stages
    settings = settings or ReliableSettings()
    if len(samples) == 0:
        raise ValueError("no samples to choose reliable pixels from (every pixel was removed "
                         f"up front: {samples.removed})")
    removed, skipped = {}, {}
    exempt = np.zeros(len(samples), dtype=bool)
    if settings.use_brightest:
        peaks = brightest_peaks(samples)
        h = samples.l[peaks] + samples.v[peaks]
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        # Eq. (2) only where the brightest sample can be a specular peak (see settings)
        near = np.sum(samples.n[peaks] * h, axis=1) >= np.cos(settings.peak_max_angle)
        skipped["brightest"] = samples.region[peaks[~near]].tolist()
        samples = samples.with_normals(peaks[near], h[near])
        exempt[peaks[near]] = True
    keep = np.ones(len(samples), dtype=bool)
    last = "input"
    if settings.use_curvature:
        ok = np.isfinite(samples.curvature) & (
            np.abs(samples.curvature) <= settings.curvature_threshold)
        stage = keep & ~ok & ~exempt
        removed["curvature"] = int(np.count_nonzero(stage))
        keep &= ~stage
        last = "curvature" if removed["curvature"] else last
    if settings.use_monotonicity and keep.any():
        kept_idx = np.flatnonzero(keep)
        resid = monotone_residuals(_MonotoneInput.take(samples, kept_idx))
        bad = np.zeros(len(samples), dtype=bool)
        bad[kept_idx] = np.any(resid > np.log1p(settings.monotonicity_tolerance), axis=1)
        bad &= ~exempt
        # Eq. (1) is rejected by a region that it would mostly remove (see settings)
        kept_regions = samples.region[kept_idx]
        rank, n_regions = group_index(kept_regions)
        regions = np.zeros(n_regions, dtype=kept_regions.dtype)
        regions[rank] = kept_regions
        fraction = (np.bincount(rank, weights=bad[kept_idx], minlength=n_regions)
                    / np.bincount(rank, minlength=n_regions))
        rejected = regions[fraction > settings.monotonicity_max_fraction]
        skipped["monotonicity"] = rejected.tolist()
        stage = bad & ~np.isin(samples.region, rejected)
        removed["monotonicity"] = int(np.count_nonzero(stage))
        keep &= ~stage
        last = "monotonicity" if removed["monotonicity"] else last
    if not keep.any():
        raise ValueError(f"no reliable pixels left after the {last} stage "
                         f"(removed: {removed}); loosen its threshold or add photos")
    index = np.flatnonzero(keep)
    peaks_out = np.flatnonzero(exempt[index])
    return samples.subset(index), ReliableReport(
        input=len(samples), removed=removed, peaks=peaks_out, kept=len(index),
        skipped={stage: regions for stage, regions in skipped.items() if regions})


def trial_candidates(
    basis: Basis,
    candidates: Samples,
    n_samples: int,
    n_trials: int,
    rng: np.random.Generator | int | None,
    subset_fraction: float = 0.5,
    peaks: np.ndarray | None = None,
    timings: dict | None = None,
    criterion: str = "risk",
) -> list[tuple[reconstruct.Reconstruction, np.ndarray]]:
    """The paper's random-subset reconstructions (Sec. 3.2) for one region.

    Each trial draws ``subset_fraction`` of the candidates at random, chooses
    ``n_samples`` optimal cells among them (``criterion``: ``"risk"`` or
    ``"condition"``, see ``sampling.optimal_cells``), and reconstructs from
    every drawn sample in those cells (plus the ``peaks`` samples, always).
    Returns ``[(Reconstruction, sample indices used)]``, one per trial; the
    same seed gives the same trials. ``timings``: if given, the wall seconds of
    the cell choice and of the reconstruction are added to its ``"sampling"``
    and ``"reconstruction"`` entries.
    """
    if not 0 < subset_fraction <= 1:
        raise ValueError(f"subset_fraction must be in (0, 1], got {subset_fraction}")
    rng = np.random.default_rng(rng)
    peaks = np.zeros(0, dtype=np.int64) if peaks is None else np.asarray(peaks)
    timings = {} if timings is None else timings
    trials = []
    for child in rng.spawn(n_trials):
        t0 = time.perf_counter()
        size = max(int(round(subset_fraction * len(candidates))), min(n_samples, len(candidates)))
        drawn = np.sort(child.choice(len(candidates), size=size, replace=False))
        cells = sampling.optimal_cells(basis, candidates.cells[drawn], n_samples, child,
                                       criterion=criterion)
        chosen = np.isin(merl.linear_index(candidates.cells[drawn]), merl.linear_index(cells))
        used = np.union1d(drawn[chosen], peaks)
        t1 = time.perf_counter()
        rec = reconstruct.reconstruct(basis, candidates.cells[used], candidates.rho[used])
        t2 = time.perf_counter()
        timings["sampling"] = timings.get("sampling", 0.0) + (t1 - t0)
        timings["reconstruction"] = timings.get("reconstruction", 0.0) + (t2 - t1)
        trials.append((rec, used))
    return trials
