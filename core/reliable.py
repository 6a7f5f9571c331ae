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
   isotonic (non-decreasing) fit of rho against n.h is made and samples whose
   relative residual ``|rho - fit| / fit`` exceeds a tolerance in any channel go.
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
from .observations import Samples

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709


@dataclasses.dataclass(frozen=True)
class ReliableSettings:
    """Switches and thresholds of the reliable region (names as in the job file)."""

    use_curvature: bool = True
    curvature_threshold: float = 0.2
    use_monotonicity: bool = True
    monotonicity_tolerance: float = 0.5
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
        h, w = samples.shapes[view]
        image = np.full((h + 2, w + 2), np.nan, dtype=np.float32)
        r, c = samples.pixel[sel, 0] + 1, samples.pixel[sel, 1] + 1
        image[r, c] = lum[sel]
        windows = np.stack([image[r + dr, c + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
        score[sel] = np.nanmedian(windows, axis=0)
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
    """(N, 3) relative residual of rho against its region's isotonic fit in n.h."""
    h = samples.l + samples.v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ndoth = np.sum(samples.n * h, axis=1)
    out = np.zeros_like(samples.rho)
    for region in np.unique(samples.region):
        sel = np.flatnonzero(samples.region == region)
        order = sel[np.argsort(ndoth[sel], kind="stable")]
        for c in range(3):
            y = samples.rho[order, c]
            fit = isotonic_regression(y, increasing=True).x
            scale = np.maximum(fit, 1e-6 * max(float(np.median(y)), 1e-12))
            out[order, c] = np.abs(y - fit) / scale
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
        bad[kept_idx] = np.any(resid > settings.monotonicity_tolerance, axis=1)
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
