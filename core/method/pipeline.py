"""The method end to end on arrays: photos + G-buffers -> one BRDF table per region.

This is Ono et al. (2017) Fig. 2 after the geometry exists: observations
(``core.method.observations``), the reliable region (Sec. 3.1, ``core.method.reliable``),
random-subset reconstructions from optimal samples (Sec. 3.2,
``core.method.reliable.trial_candidates``) and selection by the KL divergence of
rendered against photographed intensities (``core.method.selection``, the fast numpy
path). It knows nothing of Blender: the operators gather the arrays (photos
read from files, G-buffers rendered by Cycles) and write the result back.

Regions are handled one at a time, as the paper handles one material. A region
that no photo sees, or that keeps fewer than ``min_reliable_samples`` reliable
samples, is *skipped with a reason*, never guessed; if every region is skipped,
:func:`run` raises ``ValueError`` with one sentence.

Long runs report progress through a callback and stop between steps when a
``cancelled`` callable returns True (raising :class:`Cancelled`), so an
operator can run this in a worker thread and keep the interface responsive.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..brdf.basis import Basis
from ..progress import Cancelled as Cancelled  # re-exported: what run() raises
from ..progress import check
from . import observations, refine, reliable, sampling, selection
from .observations import Samples
from .refine import PHOTO_CONSISTENT

# What follows the KL selection (``refine``): nothing (the paper's method), the
# chosen trial refitted to each photo's radiance sum ("energy", the default:
# ``refine.energy_consistent``) or to every observed pixel ("photo":
# ``refine.photo_consistent``, for accurate normals)
REFINEMENTS = ("none", "energy", "photo")


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoInput:
    """One lit photo and the G-buffers of the scan seen by its camera.

    photo: (H, W, 3) linear radiance (NaN/Inf = unusable pixel). normal,
    position: (H, W, 3) world space (scene units). visibility: (H, W) in [0, 1].
    region: (H, W) int, -1 = not the target object. camera_center: (3,) world
    space. light: (3,) world direction towards the distant light. irradiance:
    scalar or (3,) on a surface facing the light. mask: optional (H, W) bool of
    pixels the user allows. saturated: optional (H, W) bool of pixels at the
    camera's white level (removed up front and counted). name: for reports.
    uv: optional (H, W, 2) the scan's UV map at each pixel (u right, v up; NaN
    where there is none), for textured regions (``core.method.textured``).
    footprint_normal: optional (H, W, S, 3) the scan's normals at S points spread
    over each pixel (NaN off the object): the refits to every pixel then predict
    a pixel as the mean over its area (``observations.observe``).
    """

    photo: np.ndarray
    normal: np.ndarray
    position: np.ndarray
    visibility: np.ndarray
    region: np.ndarray
    camera_center: np.ndarray
    light: np.ndarray
    irradiance: float | np.ndarray = 1.0
    mask: np.ndarray | None = None
    name: str = ""
    saturated: np.ndarray | None = None
    uv: np.ndarray | None = None
    footprint_normal: np.ndarray | None = None


@dataclasses.dataclass(frozen=True)
class PipelineSettings:
    """Every setting of a run (the panel's and the job file's ``[settings]``).

    n_samples: optimal MERL cells per trial (the paper uses 6). sampler: the
    criterion that chooses them, "condition" (the paper's condition number, the
    default: in the photo pipeline it measured as well as the risk or better,
    docs/results.md) or "risk" (Bayes risk of the reconstruction, the core's
    default for exact values); ``core.method.sampling``. refine: what follows
    the selection, one of :data:`REFINEMENTS` ("energy" by default; "none" is
    the paper's method). photo_consistent: with the energy refinement, the
    relative RMSE per photo (dimensionless, >= 0) at or below which the chosen
    trial refitted to every pixel replaces it, if it also predicts each photo
    from the others as well (:func:`refine_chosen`); 0 turns this off.
    n_trials: random-subset reconstructions per region. subset_fraction: share
    of the reliable samples each trial draws from. min_reliable_samples: a
    region with fewer reliable samples is skipped. kl_bins: histogram bins of
    the KL criterion. seed: every random choice; same seed, same result.
    """

    reliable: reliable.ReliableSettings = reliable.ReliableSettings()
    observation: observations.ObservationSettings = observations.ObservationSettings()
    n_samples: int = 20
    n_trials: int = 16
    subset_fraction: float = 0.5
    min_reliable_samples: int = 20
    kl_bins: int = 64
    seed: int = 0
    sampler: str = "condition"
    refine: str = "energy"
    photo_consistent: float = PHOTO_CONSISTENT

    def __post_init__(self):
        for name in ("n_samples", "n_trials", "min_reliable_samples", "kl_bins"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not 0 < self.subset_fraction <= 1:
            raise ValueError(f"subset_fraction must be in (0, 1], got {self.subset_fraction}")
        if self.sampler not in sampling.CRITERIA:
            raise ValueError(f"sampler must be one of {', '.join(sampling.CRITERIA)}, "
                             f"got {self.sampler!r}")
        if not (np.isfinite(self.photo_consistent) and self.photo_consistent >= 0.0):
            raise ValueError("photo_consistent must be a finite number >= 0, "
                             f"got {self.photo_consistent}")
        if self.refine not in REFINEMENTS:
            raise ValueError(f"refine must be one of {', '.join(REFINEMENTS)}, "
                             f"got {self.refine!r}")


class CandidateTables(Sequence):
    """Every trial's table, expanded from its coefficients when asked for
    (``[t]``: (3, 90, 90, 180) float64, 1/sr; not kept, so holding the trials costs
    their coefficients, not 16 full tables). ``reconstructions``: the trials."""

    def __init__(self, reconstructions: list):
        self.reconstructions = list(reconstructions)

    def __len__(self) -> int:
        return len(self.reconstructions)

    def __getitem__(self, t):
        if isinstance(t, slice):
            return [self[i] for i in range(*t.indices(len(self)))]
        return self.reconstructions[t].expand()


@dataclasses.dataclass(frozen=True, eq=False)
class RefineInputs:
    """What :func:`refine_chosen` needs to refit a region's chosen trial.

    method: "energy" or "photo" (:data:`REFINEMENTS` but "none"). basis: the run's
    Basis. observed: the region's observed samples after the up-front removals
    (``Samples``, N), at most ``refine.MAX_REFIT_SAMPLES`` of them
    (``refine.refit_samples``). trusted: the reliable region's samples (M; the same
    share of them as of the observed). options: keyword
    arguments of the refit (``peak_bound`` for the energy refit). photo_consistent:
    the run's setting (``PipelineSettings.photo_consistent``). normalised: the
    photos were normalised with an earlier table (a textured region's,
    ``core.method.textured``), so they are not independent of the refit the judge
    weighs against the trial: a refit kept that way must also reflect no more
    than ``refine.MAX_ALBEDO`` of the light it receives (:func:`refine_chosen`)."""

    method: str
    basis: Basis
    observed: Samples
    trusted: Samples
    options: dict
    photo_consistent: float = 0.0
    normalised: bool = False


@dataclasses.dataclass(eq=False)
class RegionResult:
    """Outcome for one region.

    status: "ok" or "skipped" (then ``reason`` says why, in one sentence).
    counts: samples at each stage: ``observed`` (after the up-front removals,
    which are in ``removed_up_front``), ``removed`` per reliable stage,
    ``reliable``, ``refit`` (the observed samples the refinement reads, at most
    ``refine.MAX_REFIT_SAMPLES``, and ``refit_trusted``, the same share of the
    reliable ones; absent without a refinement), and
    ``saturated``: the region's pixels at or above the clip level (removed up
    front). Where there are any, Eq. (2) (the brightest pixel
    as the peak) is not applied: the peak was clipped, so the brightest pixel
    left is on the highlight's edge; ``skipped_assumptions["brightest"]`` says so.
    skipped_assumptions: per reliable stage, whether the data rejected its
    assumption in this region (see ``ReliableSettings``).
    table: (3, 90, 90, 180) float64 of the chosen trial (None when skipped).
    candidates: every trial's table (:class:`CandidateTables`, expanded on access),
    for the Cycles selection path.
    kl: (T,) KL score per trial, nats; winner: index of the chosen trial.
    trials: per-trial summaries (condition number, samples used, eta).
    observed_pixels, reliable_pixels: (N, 3) int64 (view, row, column) of the
    region's samples before and after the reliable-region stages (for pictures).
    timings: wall seconds per stage of this region: ``reliable``, ``sampling``
    (optimal cell choice), ``reconstruction`` (the fits), ``selection`` (KL, from
    each trial's coefficients at the photos' cells), ``expansion`` (the chosen
    trial's full table), ``refinement`` (when on).
    refinement: with a refinement on, its ``method``, the chosen ``trial``, and the
    chosen trial's relative RMSE against the observed pixels and its energy ratio
    (``refine.energy_ratio``: predicted over photographed radiance, summed over
    them) ``before`` and ``after`` the refit (empty when off), and the chosen
    trial's ratio per photo, ``energy_per_photo`` (``refine.energy_ratios``). The
    energy refit also records ``normal_noise_deg`` (``refine.normal_noise`` over
    the region), and ``skipped``, one sentence, where the chosen trial is kept:
    that noise is above ``refine.MAX_NORMAL_NOISE_DEG``, the photos were
    ``normalised`` by a texture and the trial's energy ratio is within
    ``refine.ENERGY_TOLERANCE`` of 1 (the albedo was fitted to the trial), or the
    photos' ratios scatter by more than their mean misses 1
    (``refine.energy_agreement``) and the refit's ratios
    (``energy_per_photo_after``) still miss them by more than
    ``refine.ENERGY_RECONCILED`` (``refine.energy_misfit``: no table meets every
    photo's sum).
    refine_inputs: what :func:`refine_chosen` needs to refit another winner (the
    Cycles path's); None when the refinement is off.
    """

    region: int
    status: str
    reason: str = ""
    counts: dict = dataclasses.field(default_factory=dict)
    skipped_assumptions: dict = dataclasses.field(default_factory=dict)
    table: np.ndarray | None = None
    candidates: list = dataclasses.field(default_factory=list)
    kl: np.ndarray | None = None
    winner: int = -1
    trials: list = dataclasses.field(default_factory=list)
    observed_pixels: np.ndarray | None = None
    reliable_pixels: np.ndarray | None = None
    selection: dict = dataclasses.field(default_factory=lambda: {"path": "fast"})
    timings: dict = dataclasses.field(default_factory=dict)
    refinement: dict = dataclasses.field(default_factory=dict)
    refine_inputs: RefineInputs | None = dataclasses.field(default=None, repr=False)

    def summary(self) -> dict:
        """JSON-friendly summary (no arrays) for ``report.json``."""
        return {
            "region": int(self.region), "status": self.status, "reason": self.reason,
            "counts": self.counts, "skipped_assumptions": self.skipped_assumptions,
            "winner": int(self.winner),
            "kl": None if self.kl is None else [float(k) for k in self.kl],
            "trials": self.trials, "selection": self.selection, "timings_s": self.timings,
            "refinement": self.refinement,
        }


@dataclasses.dataclass(eq=False)
class PipelineResult:
    """All regions, the per-photo up-front removal counts, and wall time per stage (s)."""

    regions: list
    photo_counts: list
    timings: dict

    def summary(self) -> dict:
        return {"regions": [r.summary() for r in self.regions],
                "photos": self.photo_counts, "timings_s": self.timings}


def observe_photos(inputs: Sequence[PhotoInput], settings: PipelineSettings,
                   progress=None, cancelled=None) -> tuple[observations.Samples, list]:
    """Samples of every photo, concatenated (view index = position in ``inputs``),
    and per photo a dict of the samples kept and the pixels removed per reason."""
    parts = []
    for i, p in enumerate(inputs):
        check(cancelled)
        if progress:
            progress(i / max(len(inputs), 1), f"observing photo {i + 1}/{len(inputs)}")
        parts.append(observations.observe(
            p.photo, p.normal, p.position, p.visibility, p.region, p.camera_center, p.light,
            p.irradiance, p.mask, view_index=i, settings=settings.observation,
            saturated=p.saturated, footprint_normal=p.footprint_normal))
    counts = [dict(name=p.name, samples=len(part), removed=part.removed)
              for p, part in zip(inputs, parts, strict=True)]
    return observations.concatenate(parts), counts


def region_views(inputs: Sequence[PhotoInput], region: int) -> list[selection.View]:
    """The photos that see ``region``, as KL views masked to that region's pixels
    (less the saturated ones: a clipped photo pixel says nothing of the candidate's
    value there)."""
    views = []
    for p in inputs:
        mask = np.asarray(p.region) == region
        if p.mask is not None:
            mask &= np.asarray(p.mask, dtype=bool)
        if p.saturated is not None:
            mask &= ~np.asarray(p.saturated, dtype=bool)
        if not mask.any():
            continue
        views.append(selection.View(photo=p.photo, normal=p.normal, visibility=p.visibility,
                                    mask=mask, position=p.position,
                                    camera_center=p.camera_center, light=p.light,
                                    irradiance=p.irradiance))
    return views


def saturated_pixels(inputs: Sequence[PhotoInput], region: int,
                     clip_level: float | None) -> int:
    """Pixels of ``region`` (and of each photo's mask) that are saturated: marked in
    the photo's ``saturated`` mask, or with any channel at or above ``clip_level``
    (None: no level), over all photos."""
    total = 0
    for p in inputs:
        if clip_level is None and p.saturated is None:
            continue
        inside = np.asarray(p.region) == region
        if p.mask is not None:
            inside &= np.asarray(p.mask, dtype=bool)
        hit = np.zeros(inside.shape, dtype=bool)
        if p.saturated is not None:
            hit |= np.asarray(p.saturated, dtype=bool)
        if clip_level is not None:
            hit |= np.any(np.asarray(p.photo) >= clip_level, axis=-1)
        total += int(np.count_nonzero(inside & hit))
    return total


def run_region(
    basis: Basis,
    samples: observations.Samples,
    inputs: Sequence[PhotoInput],
    region: int,
    settings: PipelineSettings,
    rng: np.random.Generator,
    progress=None,
    cancelled=None,
    normalised: bool = False,
) -> RegionResult:
    """Reliable region, trials and KL selection for one region's samples
    (``normalised``: as :func:`run`'s)."""
    sel = np.flatnonzero(samples.region == region)
    result = RegionResult(region=int(region), status="skipped",
                          counts={"observed": int(len(sel))})
    if len(sel) == 0:
        result.reason = f"region {region}: no photo sees it with usable pixels"
        return result
    result.observed_pixels = np.column_stack([samples.view[sel], samples.pixel[sel]])
    t0 = time.perf_counter()
    rel = settings.reliable
    saturated = saturated_pixels(inputs, region, settings.observation.clip_level)
    if saturated and rel.use_brightest:
        # Eq. (2) takes the brightest pixel for the peak; with the highlight's core
        # clipped (and removed), the brightest one left sits on the highlight's edge
        rel = dataclasses.replace(rel, use_brightest=False)
    try:
        observed = samples.subset(sel)
        cand, report = reliable.reliable_candidates(observed, rel)
    except ValueError as error:
        result.reason = f"region {region}: {error}"
        return result
    finally:
        result.timings["reliable"] = time.perf_counter() - t0
    result.counts.update(removed=report.removed, reliable=report.kept,
                         saturated=int(saturated))
    result.reliable_pixels = np.column_stack([cand.view, cand.pixel])
    result.skipped_assumptions = dict(report.skipped)
    if rel is not settings.reliable:
        result.skipped_assumptions["brightest"] = [int(region)]
    if report.kept < settings.min_reliable_samples:
        result.reason = (f"region {region}: only {report.kept} reliable samples "
                         f"(fewer than {settings.min_reliable_samples})")
        return result
    trials = []
    for t, child in enumerate(rng.spawn(settings.n_trials)):
        check(cancelled)
        if progress:
            progress(t / settings.n_trials, f"region {region}: trial {t + 1}/{settings.n_trials}")
        trials += reliable.trial_candidates(basis, cand, settings.n_samples, 1, child,
                                              settings.subset_fraction, report.peaks,
                                              timings=result.timings,
                                              criterion=settings.sampler)
    check(cancelled)
    if progress:
        progress(1.0, f"region {region}: KL selection over {len(trials)} trials")
    t0 = time.perf_counter()
    chosen = selection.select_by_kl([rec for rec, _ in trials],
                                    region_views(inputs, region), n_bins=settings.kl_bins)
    result.timings["selection"] = time.perf_counter() - t0
    result.status = "ok"
    result.kl = chosen.kl
    result.winner = int(chosen.winner)
    if settings.refine != "none":  # the paper's mode chooses by the KL alone
        eligible = selection.photo_eligible(chosen.rmse)
        result.winner = selection.eligible_winner(chosen.kl, eligible)
        result.selection = dict(result.selection, **_photo_check(chosen, eligible))
    method = settings.refine
    if method == "energy":  # kept only where the scan's normals are not pixel noise
        noise = refine.normal_noise([p.normal for p in inputs],
                                    [np.asarray(p.region) == region for p in inputs])
        result.refinement = {"method": "energy", "trial": int(result.winner),
                             "normal_noise_deg": noise}
        if noise > refine.MAX_NORMAL_NOISE_DEG:
            method = "none"
            result.refinement["skipped"] = (
                f"the scan's normals change from pixel to pixel by a median {noise:.1f} "
                f"degrees (more than {refine.MAX_NORMAL_NOISE_DEG:g}), so the photos' "
                "energy was not refitted")
    if method == "none":
        t0 = time.perf_counter()
        result.table = trials[result.winner][0].table  # the only full table expanded
        result.timings["expansion"] = time.perf_counter() - t0
    result.candidates = CandidateTables([rec for rec, _ in trials])
    result.trials = [dict(rec.summary(), samples_used=int(len(used))) for rec, used in trials]
    if method != "none":
        # Eq. (2)'s bound on the peak where Eq. (2) holds (not with the peak clipped);
        # refitted to every pixel, the albedo's bound is refine_chosen's
        options = {"peak_bound": rel.use_brightest} if method == "energy" else {}
        # a large region: a uniform draw of its observed and trusted samples
        refit, refit_trusted = refine.refit_samples(observed, cand)
        result.counts.update(refit=len(refit), refit_trusted=len(refit_trusted))
        result.refine_inputs = RefineInputs(method, basis, refit, refit_trusted, options,
                                            settings.photo_consistent, normalised)
        check(cancelled)
        if progress:
            progress(1.0, f"region {region}: refining the chosen table "
                     + ("(the photos' energy)" if method == "energy" else "to the photos"))
        refine_chosen(result, cancelled=cancelled)
    return result


def _photo_check(chosen: selection.SelectionResult, eligible: np.ndarray) -> dict:
    """The report's record of the photos' check on the trials (``selection.photo_eligible``):
    each trial's relative RMSE against the photos, the trials it excluded and, where
    it moved the choice, the KL's own winner."""
    record = {"photo_rmse": [_finite_or_none(x) for x in chosen.rmse],
              "photo_excluded": [int(i) for i in np.flatnonzero(~eligible)]}
    if not eligible[chosen.winner]:
        record["kl_winner"] = int(chosen.winner)
    return record


def refine_chosen(result: RegionResult, photo_consistent: float | None = None,
                  cancelled: Callable[[], bool] | None = None) -> None:
    """Refit ``result``'s chosen trial (``result.winner``) with the run's refinement
    (``core.method.refine.energy_consistent`` or ``photo_consistent``, on the
    region's observed pixels) and make it ``result.table``; records
    ``refinement`` and its time. Nothing to do when the refinement is off
    (``refine_inputs`` None).

    The energy refinement is judged by the photos: the chosen trial is also
    refitted to every observed pixel (``refine.photo_consistent``; it and its
    held-out refits reflect no more than
    ``refine.ALBEDO_BOUND`` of the light they receive, unless that bound keeps it
    from a photo the free refit meets: then the irradiance given is too low for
    the photos, the refit is free and ``every_pixel["bound_refused"]`` says so;
    the "photo" refinement is bounded the same way, with ``photo_consistent`` or
    ``refine.PHOTO_CONSISTENT`` as the photos' test, ``refinement["albedo_bound"]``
    the bound it kept), and where that
    refit reproduces each photo to a relative RMSE of ``photo_consistent`` or less
    (default: the run's ``PipelineSettings.photo_consistent``; 0: never) and,
    refitted without each photo in turn, predicts the photo left out
    (``refine.held_out_rmse``) and hardly moves on the rendered sphere
    (``refine.photo_dependence``), both to the same level in the median over
    photos, or predicts the photo left out to ``refine.TRIAL_SHARE`` of the chosen
    trial's own error on the photos or less (median over photos; where the
    photos were ``normalised`` with an earlier table, only if its directional
    albedo stays within ``refine.MAX_ALBEDO``), it is the table: the scan's
    normals are then good enough for the photos to be read pixel by pixel, which
    the energy refit does not do. ``refinement["every_pixel"]`` records its
    ``relative_rmse``, ``per_photo`` and ``held_out`` errors, its ``dependence``
    on each photo, the trial's error on each photo (``trial_per_photo``), its
    ``largest_albedo`` where asked, whether it was ``kept`` and ``by`` which
    test ("its own errors" or "against the trial"); ``refinement["table"]`` says
    which became the table: "trial", "energy" or "every_pixel". Where that refit
    reproduces each photo to ``photo_consistent`` but is not kept, the photos can
    still be read pixel by pixel, so an energy refit that reproduces them worse
    (``refine.relative_rmse``) than the chosen trial is not kept either: the trial
    is the table and ``refinement["skipped"]`` says why. ``cancelled`` is
    polled between the refits (:class:`Cancelled`; the result is then left as it
    was)."""
    if result.refine_inputs is None:
        return
    judge = (result.refine_inputs.photo_consistent if photo_consistent is None
             else float(photo_consistent))
    if not (np.isfinite(judge) and judge >= 0.0):
        raise ValueError(f"photo_consistent must be a finite number >= 0, got {judge}")
    inp = result.refine_inputs
    method, basis, observed, trusted = inp.method, inp.basis, inp.observed, inp.trusted
    t0 = time.perf_counter()
    start = result.candidates.reconstructions[result.winner]
    recorded = {k: v for k, v in result.refinement.items() if k == "normal_noise_deg"}
    energy = refine.energy_ratio(start, observed)
    ratios = refine.energy_ratios(start, observed)
    recorded.update(energy_per_photo=[float(r) for r in ratios], method=method,
                    trial=int(result.winner), energy_before=energy)
    # refitted to every pixel, a table reflects no more than a surface's limit of the
    # light it receives, unless the photos say it reflects more (_bound_refused); on
    # photos divided by a texture too: the table is then at the region's mean colour,
    # at or below its brightest texel's, which is a surface's
    bound = refine.ALBEDO_BOUND
    readable = False  # does a refit to every pixel reproduce each photo to the judge?
    if method == "energy" and judge > 0.0:  # the photos judge first: read pixel by pixel?
        every, verdict = _every_pixel_verdict(
            basis, start, observed, trusted, judge, cancelled,
            trial_share=refine.TRIAL_SHARE,
            max_albedo=refine.MAX_ALBEDO if inp.normalised else None, bound=bound)
        check(cancelled)
        if _presses_bound(every, verdict["per_photo"], bound, judge):
            free, free_verdict = _every_pixel_verdict(
                basis, start, observed, trusted, judge, cancelled,
                trial_share=refine.TRIAL_SHARE, bound=None)
            check(cancelled)
            if _reads(free_verdict["per_photo"], judge):
                free_verdict["bound_refused"] = _bound_refused(
                    verdict["per_photo"], free_verdict["per_photo"], bound)
                every, verdict = free, free_verdict
        recorded["every_pixel"] = verdict
        readable = _reads(verdict["per_photo"], judge)
        if verdict["kept"]:
            result.table = every.table
            result.refinement = {
                **recorded, "table": "every_pixel",
                "before": refine.relative_rmse(start, observed),
                "after": verdict["relative_rmse"],
                "energy_after": refine.energy_ratio(every, observed),
                "energy_per_photo_after": [float(r) for r in refine.energy_ratios(
                    every, observed)]}
            result.timings["refinement"] = time.perf_counter() - t0
            return
    skipped = None
    if (method == "energy" and inp.normalised
            and abs(energy - 1.0) <= refine.ENERGY_TOLERANCE):
        skipped = (f"the photos were divided by an albedo fitted to the chosen trial, "
                   f"whose radiance is already within "
                   f"{100 * refine.ENERGY_TOLERANCE:g} % of theirs "
                   f"({energy:.3f} of it), so it was kept as it is")
    if not skipped:
        if method == "energy":
            refined = refine.energy_consistent(basis, start, observed, trusted, **inp.options)
        else:
            refined = refine.photo_consistent(basis, start, observed, trusted,
                                              max_albedo=bound, **inp.options)
            at = judge if judge > 0.0 else refine.PHOTO_CONSISTENT
            per_photo = [_finite_or_none(r) for r in
                         refine.relative_rmse_per_photo(refined, observed)]
            if _presses_bound(refined, per_photo, bound, at):
                check(cancelled)
                free = refine.photo_consistent(basis, start, observed, trusted, **inp.options)
                free_per_photo = [_finite_or_none(r) for r in
                                  refine.relative_rmse_per_photo(free, observed)]
                if _reads(free_per_photo, at):
                    recorded["bound_refused"] = _bound_refused(per_photo, free_per_photo,
                                                               bound)
                    refined, bound = free, None
            recorded["albedo_bound"] = bound
        before, after_rmse = (refine.relative_rmse(start, observed),
                              refine.relative_rmse(refined, observed))
        after = refine.energy_ratios(refined, observed)
        recorded["energy_per_photo_after"] = [float(r) for r in after]
        if method == "energy" and refine.photos_disagree_unreconciled(ratios, after):
            skipped = (
                "the photos disagree on the chosen trial's energy (each photo's ratio "
                f"{', '.join(f'{r:.2f}' for r in ratios)}) by more than they miss it "
                "together, and the refit does not reconcile them (ratios after "
                f"{', '.join(f'{r:.2f}' for r in after)}), so the trial was kept as it is")
        elif readable and not after_rmse <= before:
            skipped = (
                "the scan's normals let the photos be read pixel by pixel (a refit "
                f"to every pixel reproduces each to {judge:g}), and the energy refit "
                f"reproduces them worse than the chosen trial ({before:.3f} -> "
                f"{after_rmse:.3f} relative RMSE), so the trial was kept as it is")
    if skipped:
        result.table = start.table  # nothing the photos agree on to give back
        result.refinement = {**recorded, "skipped": skipped, "table": "trial"}
    else:
        result.table = refined.table
        result.refinement = {
            **recorded, "before": before, "after": after_rmse,
            "energy_after": refine.energy_ratio(refined, observed),
            "table": "energy" if method == "energy" else "every_pixel"}
    result.timings["refinement"] = time.perf_counter() - t0


def _every_pixel_verdict(basis, start, observed, trusted, judge: float, cancelled=None,
                         trial_share: float = 0.0, max_albedo: float | None = None,
                         bound: float | None = None):
    """The chosen trial refitted to every observed pixel (``refine.photo_consistent``;
    where ``bound`` is given, it and the held-out refits reflect no more than that
    of the light they receive, its ``max_albedo``) and whether the photos keep it.
    It must reproduce each photo to a relative RMSE of ``judge`` or less; then
    (asked only then) it is refitted without each photo in turn, and kept if, in
    the median over photos, either
    - the refits predict the photo left out (``refine.held_out_rmse``) and move on
      the rendered sphere (``refine.photo_dependence``) by ``judge`` or less ("its
      own errors"), or
    - the refits predict the photo left out to ``trial_share`` of the chosen
      trial's own relative RMSE on the photos or less ("against the trial"; 0:
      not asked) and, if ``max_albedo`` is given, reflect no more than that of
      the light it receives (its largest directional albedo, read on the
      quadrature its bound holds, ``refine.reconstruction_albedo``).
    Returns the refit and a JSON-ready record (``relative_rmse``, ``per_photo``,
    ``held_out``, ``dependence``, ``trial_per_photo``, ``kept``, ``by``,
    ``largest_albedo`` (None where not asked), ``threshold``, ``trial_share``,
    ``albedo_bound`` (``bound``);
    NaN, a black photo's or a single photo's, as None, and never kept)."""
    every = refine.photo_consistent(basis, start, observed, trusted, max_albedo=bound)
    per_photo = refine.relative_rmse_per_photo(every, observed)
    kept = bool(np.all(per_photo <= judge))
    held_out = dependence = trial = albedo = None
    by = None
    if kept:
        fits = refine.held_out_refits(basis, start, observed, trusted, cancelled=cancelled,
                                      max_albedo=bound)
        held_out = refine.held_out_rmse(fits, observed)
        dependence = refine.photo_dependence(every, fits)
        trial = refine.relative_rmse_per_photo(start, observed)
        predicted = bool(np.all(np.isfinite(held_out)))
        if (predicted and np.all(np.isfinite(dependence))
                and np.median(held_out) <= judge and np.median(dependence) <= judge):
            by = "its own errors"
        elif (predicted and trial_share > 0.0 and np.all(np.isfinite(trial))
              and np.median(held_out) <= trial_share * np.median(trial)):
            if max_albedo is not None:  # better than the trial, but still a surface?
                # read on the cells its bound holds (refine.ALBEDO_NODES)
                albedo = refine.reconstruction_albedo(every)
            if max_albedo is None or albedo <= max_albedo:
                by = "against the trial"
        kept = by is not None
    return every, {
        "relative_rmse": _finite_or_none(refine.relative_rmse(every, observed)),
        "kept": kept, "by": by, "per_photo": [_finite_or_none(r) for r in per_photo],
        "held_out": None if held_out is None else [_finite_or_none(r) for r in held_out],
        "dependence": None if dependence is None else [_finite_or_none(r) for r in dependence],
        "trial_per_photo": None if trial is None else [_finite_or_none(r) for r in trial],
        "largest_albedo": None if albedo is None else _finite_or_none(albedo),
        "threshold": judge, "trial_share": trial_share, "albedo_bound": bound}


def refinement_notes(refinement: dict) -> list[str]:
    """The sentences of a region's ``refinement`` record (``RegionResult.refinement``,
    as in ``report.json``) its user should read: where the photos refused the
    albedo bound, its irradiance is likely too low."""
    notes = [refinement.get("bound_refused"),
             (refinement.get("every_pixel") or {}).get("bound_refused")]
    return [n for n in notes if n]


def region_notes(summary: dict) -> list[str]:
    """The sentences on a region its user should read, from its summary
    (:meth:`RegionResult.summary`, as in ``report.json``): the refinement's
    (:func:`refinement_notes`) and, where the photos' highlight is clipped
    (``counts["saturated"]``), that its peak's height was not photographed."""
    counts = summary.get("counts") or {}
    clipped = int(counts.get("saturated") or 0)
    notes = []
    if clipped:
        seen = clipped + int(counts.get("observed") or 0)
        notes.append(
            f"{clipped} of its pixels ({100.0 * clipped / seen:.1f} % of those the photos "
            "show of it) are clipped, the brightest of its highlight among them: the "
            "peak's height was not photographed, so the material's gloss is an estimate "
            "(photograph it with a shorter exposure, or merge a bracket, to measure it)")
    return notes + refinement_notes(summary.get("refinement") or {})


def _reads(per_photo, judge: float) -> bool:
    """Whether a refit reproduces each photo (``per_photo``: relative RMSE, None
    where not finite) to ``judge`` or less."""
    return all(r is not None and r <= judge for r in per_photo)


def _presses_bound(refit, per_photo, bound: float | None, judge: float) -> bool:
    """Whether a refit bounded in albedo at ``bound`` misses a photo by more than
    ``judge`` while it presses against the bound (``refine.BOUND_PRESSED``): the
    bound may be what keeps it from the photos."""
    return (bound is not None and not _reads(per_photo, judge)
            and refine.reconstruction_albedo(refit) >= refine.BOUND_PRESSED * bound)


def _bound_refused(bounded, free, bound: float) -> str:
    """The report's sentence where the photos refuse the albedo bound."""
    def listed(per_photo):
        return ", ".join("-" if r is None else f"{r:.2f}" for r in per_photo)

    return (f"a table reflecting no more than {bound:g} of the light it receives misses "
            f"the photos (relative RMSE per photo {listed(bounded)}) where one without "
            f"that bound meets them ({listed(free)}): the photos say the surface "
            "reflects more light than the irradiance given lets it, so that irradiance "
            "is likely too low (check it, or give a gray card), and the refit was not "
            "bounded")


def _finite_or_none(value) -> float | None:
    return float(value) if np.isfinite(value) else None


def run(
    basis: Basis,
    inputs: Sequence[PhotoInput],
    settings: PipelineSettings | None = None,
    regions: Sequence[int] | None = None,
    progress: Callable[[float, str], None] | None = None,
    cancelled: Callable[[], bool] | None = None,
    normalised: bool = False,
) -> PipelineResult:
    """Reconstruct one BRDF per region from lit photos and their G-buffers.

    ``regions``: the region ids to reconstruct (default: every id >= 0 seen in
    any G-buffer). ``progress(fraction, message)`` is called between steps with
    fraction in [0, 1]; ``cancelled()`` is polled between steps. ``normalised``:
    the photos were divided by a texture estimated with an earlier table
    (``core.method.textured``); the judge then keeps an every-pixel refit that
    beats the trial only if it reflects no more than ``refine.MAX_ALBEDO`` of the
    light it receives (:func:`refine_chosen`). Raises
    ValueError with one sentence when no photo is given or every region is
    skipped, and :class:`Cancelled` when cancelled.
    """
    settings = settings or PipelineSettings()
    if not inputs:
        raise ValueError("no lit photos to reconstruct from")
    timings = {}

    def stage_progress(lo, hi):
        if progress is None:
            return None
        return lambda f, msg: progress(lo + (hi - lo) * f, msg)

    t0 = time.perf_counter()
    samples, photo_counts = observe_photos(inputs, settings, stage_progress(0.0, 0.1),
                                           cancelled)
    timings["observations"] = time.perf_counter() - t0
    if regions is None:
        seen = set()
        for p in inputs:
            seen.update(int(r) for r in np.unique(p.region) if r >= 0)
        regions = sorted(seen)
    if not regions:
        raise ValueError("the target object is not seen in any photo")
    rng = np.random.default_rng(settings.seed)
    results = []
    t0 = time.perf_counter()
    for i, (region, child) in enumerate(zip(regions, rng.spawn(len(regions)), strict=True)):
        lo = 0.1 + 0.9 * i / len(regions)
        results.append(run_region(basis, samples, inputs, int(region), settings, child,
                                  stage_progress(lo, lo + 0.9 / len(regions)), cancelled,
                                  normalised))
    timings["reliable_trials_selection"] = time.perf_counter() - t0
    for r in results:
        for stage, seconds in r.timings.items():
            timings[stage] = timings.get(stage, 0.0) + seconds
    if not any(r.status == "ok" for r in results):
        raise ValueError("no reliable pixels in any region: "
                         + "; ".join(r.reason for r in results))
    return PipelineResult(regions=results, photo_counts=photo_counts, timings=timings)

