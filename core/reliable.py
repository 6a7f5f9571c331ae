"""Reliable-region extraction (Ono et al. 2017, Sec. 3.1) and the random-subset trials.

Photogrammetry meshes are blunted, so normals are wrong where curvature is high,
and a sample with a wrong normal lands in the wrong MERL cell. Three
assumptions keep the trustworthy samples, each stage switchable and counted:

1. **Brightest peak (Eq. 2).** The brightest sample of each region is taken as
   the specular peak: its normal is set to h = normalize(l + v), so it lands in
   theta_h = 0. One pixel is fragile (noise, a hot pixel), so a sample's
   brightness is the *median* luminance of its 3 x 3 neighbourhood in its photo:
   a lone hot pixel has dim neighbours and cannot win. The corrected sample is
   exempt from the later stages (its normal is now set by assumption).
2. **Curvature.** Samples whose |H| exceeds a threshold (radians of normal turn
   per 10 pixels, see ``core.observations``), or whose H is undefined, go.
3. **Monotonicity (Eq. 1, after Higo et al. 2010).** Within a region,
   reflectance should not decrease as n.h grows. Per region and channel, an
   isotonic (non-decreasing) fit of ln(rho) against n.h is made and samples
   further than a factor (1 + tolerance) from it in any channel go.
   It works on rho, not on radiance, so the cosine falloff is divided out: a
   Lambertian region has constant rho and is a flat isotonic fit, which its
   samples match to within their noise, so diffuse-dominated regions are not
   gutted (tested). What it removes are samples that are too bright or too dark
   for their n.h, the signature of a wrong normal.

``reliable_candidates`` runs the stages; ``reconstruct_trials`` then makes the
paper's several reconstructions from random subsets (Sec. 3.2), each from
condition-optimal cells (``core.sampling``), seeded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import isotonic_regression

from . import merl, reconstruct, sampling
from .basis import Basis
from .curvature import window_nanmedian3
from .observations import Samples

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709


@dataclasses.dataclass(frozen=True)
class ReliableSettings:
    """Switches and thresholds of the reliable region (names as in the job file)."""

    use_curvature: bool = True
    curvature_threshold: float = 0.2
    use_monotonicity: bool = True
    monotonicity_tolerance: float = 1.0  # allowed factor (1 + tol) off the monotone fit
    use_brightest: bool = True


@dataclasses.dataclass(frozen=True)
class ReliableReport:
    """Counts: ``input`` samples, samples ``removed`` per stage, ``peaks`` (indices
    into the returned candidates of the peak-corrected samples), ``kept``."""

    input: int
    removed: dict
    peaks: np.ndarray
    kept: int


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
    """Index of the brightest sample (by :func:`brightness`) of each region."""
    score = brightness(samples)
    peaks = []
    for region in np.unique(samples.region):
        sel = np.flatnonzero(samples.region == region)
        peaks.append(sel[np.argmax(score[sel])])
    return np.asarray(peaks, dtype=np.int64)


def monotone_residuals(samples: Samples) -> np.ndarray:
    """(N, 3) log-ratio ``|ln(rho / fit)|`` of each sample to its region's monotone fit.

    The fit is an isotonic (non-decreasing) regression of ``ln(rho + delta)``
    against n.h, per region and channel. It is done in log space because rho
    spans orders of magnitude on glossy materials: a least-squares fit on linear
    rho is dragged up by a few highlight values and then flags hundreds of dim
    samples. delta = 1e-3 x the region's median rho keeps black samples finite.
    """
    h = samples.l + samples.v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ndoth = np.sum(samples.n * h, axis=1)
    out = np.zeros_like(samples.rho)
    for region in np.unique(samples.region):
        sel = np.flatnonzero(samples.region == region)
        order = sel[np.argsort(ndoth[sel], kind="stable")]
        for c in range(3):
            rho = samples.rho[order, c]
            delta = 1e-3 * max(float(np.median(rho)), 1e-12)
            y = np.log(np.maximum(rho, 0.0) + delta)
            out[order, c] = np.abs(y - isotonic_regression(y, increasing=True).x)
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
    removed = {}
    exempt = np.zeros(len(samples), dtype=bool)
    if settings.use_brightest:
        peaks = brightest_peaks(samples)
        h = samples.l[peaks] + samples.v[peaks]
        samples = samples.with_normals(peaks, h / np.linalg.norm(h, axis=1, keepdims=True))
        exempt[peaks] = True
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
        resid = monotone_residuals(samples.subset(kept_idx))
        bad = np.zeros(len(samples), dtype=bool)
        bad[kept_idx] = np.any(resid > np.log1p(settings.monotonicity_tolerance), axis=1)
        stage = bad & ~exempt
        removed["monotonicity"] = int(np.count_nonzero(stage))
        keep &= ~stage
        last = "monotonicity" if removed["monotonicity"] else last
    if not keep.any():
        raise ValueError(f"no reliable pixels left after the {last} stage "
                         f"(removed: {removed}); loosen its threshold or add photos")
    index = np.flatnonzero(keep)
    peaks_out = np.flatnonzero(exempt[index])
    return samples.subset(index), ReliableReport(
        input=len(samples), removed=removed, peaks=peaks_out, kept=len(index))


def reconstruct_trials(
    basis: Basis,
    candidates: Samples,
    n_samples: int,
    n_trials: int,
    rng: np.random.Generator | int | None,
    subset_fraction: float = 0.5,
    peaks: np.ndarray | None = None,
) -> list[tuple[reconstruct.Reconstruction, np.ndarray]]:
    """The paper's random-subset reconstructions (Sec. 3.2) for one region.

    Each trial draws ``subset_fraction`` of the candidates at random, chooses
    ``n_samples`` condition-optimal cells among them, and reconstructs from
    every drawn sample in those cells (plus the ``peaks`` samples, always).
    Returns ``[(Reconstruction, sample indices used)]``, one per trial; the
    same seed gives the same trials.
    """
    if not 0 < subset_fraction <= 1:
        raise ValueError(f"subset_fraction must be in (0, 1], got {subset_fraction}")
    rng = np.random.default_rng(rng)
    peaks = np.zeros(0, dtype=np.int64) if peaks is None else np.asarray(peaks)
    trials = []
    for child in rng.spawn(n_trials):
        size = max(int(round(subset_fraction * len(candidates))), min(n_samples, len(candidates)))
        drawn = np.sort(child.choice(len(candidates), size=size, replace=False))
        cells = sampling.optimal_cells(basis, candidates.cells[drawn], n_samples, child)
        chosen = np.isin(merl.linear_index(candidates.cells[drawn]), merl.linear_index(cells))
        used = np.union1d(drawn[chosen], peaks)
        rec = reconstruct.reconstruct(basis, candidates.cells[used], candidates.rho[used])
        trials.append((rec, used))
    return trials
