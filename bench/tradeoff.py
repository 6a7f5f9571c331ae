"""The speed/accuracy trade on the bunny capture, and the paper's ablation on it.

Run: ``make bench`` (or ``.venv/bin/python bench/tradeoff.py [--quick]
[--part sweep|presets|ablation]``). Writes ``bench/results/tradeoff.json`` and
``bench/results/tradeoff.png`` (the Pareto plot), and ``bench/results/ablation_bunny.json``
/ ``.png`` (``--part ablation --samples 6``, the paper's mode:
``ablation_bunny_samples6.json`` / ``.png``).

The capture: the Stanford bunny, degraded as a photogrammetry mesh (decimated,
smoothed, noisy; ``testkit/capture.py``), three lit photos from a COLMAP camera
ring, Cycles G-buffers of the truth and of the scan (``bench/capture_arrays.py``),
photos shaded from the truth's geometry with the true table plus 1 % noise.

**Basis and materials.** Every run uses the shipped default, the measured basis,
built without the material it scores (``common.default_basis_without``: the whole
pack for an analytic held-out material, the other folds' 64 for a measured one).

**Sweep** (one setting at a time away from a base point, for a glossy metal and
a rough dielectric, analytic and measured (:data:`MATERIALS`), two seeds each):
trials; samples per trial, from the paper's 6 up to every reliable sample; photo
resolution; basis size (PCA
components, the basis truncated; 80 is built); KL path (fast numpy, or Cycles
renders of each candidate table at 4/16/64 samples). Each point runs in its own
child process and records wall seconds per stage (G-buffers: the Cycles render
of the scan per photo, measured when the capture was rendered; observations,
reliable region, sampling, reconstruction (the trials' coefficients), selection,
expansion (the chosen trial's full table; with the Cycles path also its winner's,
as the extension does), bake = the lobe fit),
peak memory (the child's max RSS), and the errors against the truth: BRDF log
RMSE and the rendered-sphere relative RMSE under three evaluation lights
(``core.brdf.metrics.sphere_error``) of the chosen table and of the baked material.

**Presets**: every entry of ``brdf_addon.presets.PRESETS`` (Fast, Balanced, Accurate,
and Paper, the paper's 6 samples x 16 trials with the Cycles selection) run as points
of their own, so the README quotes what each measured.

**Held-out check** (``--part heldout``, not in ``all``): 6 samples per trial against
20 over the ablation's 19 held-out materials, seed 0 (``tradeoff_heldout.json``): the
sweep's four materials are too few to choose the samples on.

**Ablation** (the paper's Fig. 3e against Sec. 3.1): no constraints, each
constraint alone, all constraints; each with the median trial (no KL), the
KL-chosen trial, and that trial after the default's energy refit
(``refine="energy"``, ``kl_energy``: one run gives all three); the 12 analytic
held-out materials and one measured material per class
(``testkit.measured.one_per_class``) on the blunted bunny.
"""

from __future__ import annotations

import argparse
import concurrent.futures as futures
import dataclasses
import datetime
import json
import multiprocessing
import os
import pathlib
import sys
import time

import common
import numpy as np

RESULTS = common.RESULTS
NOTE = ("2-core machine shared with other jobs during the run; wall times are noisy, "
        "compare within this run")

# glossy metal, rough dielectric: analytic held-out, and the measured metal and plastic
# of testkit.measured.one_per_class (drawn at random, seed 0), each scored with the
# default (measured) basis that never saw it (common.default_basis_without)
MATERIALS = ("heldout_gold_medium", "heldout_rough_plastic", "two-layer-gold",
             "specular-black-phenolic")
SEEDS = (0, 1)
ALL = 10**6  # "every reliable sample": more cells than any region has


@dataclasses.dataclass(frozen=True)
class Point:
    """One configuration. samples = ALL with trials 1 and subset 1.0 is "all samples"."""

    material: str = MATERIALS[0]
    seed: int = 0
    resolution: tuple = (240, 180)
    photos: int = 3
    samples: int = 20
    trials: int = 16
    subset: float = 0.5
    components: int = 40
    kl: str = "fast"  # or "cycles"
    kl_samples: int = 16
    constraints: str = "all"  # all | none | curvature | monotonicity | brightest
    noise: float = 0.01
    scan: str = "blunted"  # or "exact": the scan is the ground truth (good normals)
    # what follows the selection (pipeline.REFINEMENTS): the sweep measures the trials
    # alone ("none"); a preset's point takes its keep_highlight_energy
    refine: str = "none"
    # the default (measured) basis without the material (common.default_basis_without);
    # rows of runs before 2026-12-02 (analytic basis) lack the field and are never reused
    basis: str = "measured"

    def label(self) -> str:
        return (f"samples={'all' if self.samples >= ALL else self.samples} trials={self.trials}"
                f" res={self.resolution[0]}x{self.resolution[1]} k={self.components}"
                f" kl={self.kl}{self.kl_samples if self.kl == 'cycles' else ''}"
                + (" scan=exact" if self.scan == "exact" else ""))


BASE = Point()
AXES = {
    "trials": [dict(trials=t) for t in (1, 4, 16, 64)],
    "samples": [dict(samples=s) for s in (6, 20, 80)]
               + [dict(samples=ALL, trials=1, subset=1.0)],
    "resolution": [dict(resolution=r) for r in ((120, 90), (240, 180), (480, 360), (960, 720))],
    "components": [dict(components=k) for k in (10, 20, 40, 80)],
    "kl": [dict(kl="fast")] + [dict(kl="cycles", kl_samples=s) for s in (4, 16, 64)],
    # the same two sampling choices when the scan's normals are exact
    "exact_normals": [dict(scan="exact"), dict(scan="exact", samples=ALL, trials=1, subset=1.0),
                      dict(scan="exact", samples=6)],
}
# scan_options of capture.photogrammetry_mesh that keep the ground truth as it is
EXACT_SCAN = dict(decimate_ratio=1.0, smooth_iterations=0, noise=0.0)
CONSTRAINTS = {
    "none": dict(use_curvature=False, use_monotonicity=False, use_brightest=False),
    "curvature": dict(use_curvature=True, use_monotonicity=False, use_brightest=False),
    "monotonicity": dict(use_curvature=False, use_monotonicity=True, use_brightest=False),
    "brightest": dict(use_curvature=False, use_monotonicity=False, use_brightest=True),
    "all": dict(use_curvature=True, use_monotonicity=True, use_brightest=True),
}
STAGES = ("gbuffers", "observations", "reliable", "sampling", "reconstruction", "selection",
          "expansion", "refinement", "bake")


def _basis(components: int, material: str):
    """The default (measured) basis that never saw ``material``, with ``components``
    components: built with 40 (``basis.N_COMPONENTS``) and truncated, or built with
    more."""
    from brdf_reconstruct.core.brdf import basis

    full = common.default_basis_without(material, max(components, basis.N_COMPONENTS))
    if components == full.n_components:
        return full
    return dataclasses.replace(full, Q=np.ascontiguousarray(full.Q[:, :components]),
                               singular_values=full.singular_values[:components],
                               _derived={})


def _cycles_select(point: Point, arrays, inputs, candidates):
    """(winner, seconds): KL of Cycles renders of each candidate table (the
    extension's accurate path, ``brdf_addon.cycles_select``; each table expanded
    from its trial's coefficients, timed with the renders)."""
    from types import SimpleNamespace

    import capture_arrays

    from brdf_reconstruct.brdf_addon import cycles_select

    lit = (0, 2, 4)[: point.photos]
    _truth, scan, cameras = capture_arrays.build_scene(point.resolution)
    scene = SimpleNamespace(brdf=SimpleNamespace(
        target=scan, photos=[SimpleNamespace(camera=cameras[i]) for i in lit]))
    t0 = time.perf_counter()
    _score, winner = cycles_select.select_by_cycles(scene, inputs, 0, candidates,
                                                    render_samples=point.kl_samples)
    return winner, time.perf_counter() - t0


def run_point(point: Point) -> dict:
    """Run one configuration (in a fresh process) and measure it."""
    import resource

    import capture_arrays

    from brdf_reconstruct.core.bake import fitting, lobes
    from brdf_reconstruct.core.brdf import metrics
    from brdf_reconstruct.core.method import pipeline, reliable

    arrays = capture_arrays.gbuffers(
        resolution=point.resolution, scan_options=EXACT_SCAN if point.scan == "exact" else None)
    truth = common.heldout_table(point.material)
    B = _basis(point.components, point.material)
    inputs = capture_arrays.photo_inputs(arrays, truth, noise=point.noise, seed=point.seed,
                                         views=range(point.photos))
    settings = pipeline.PipelineSettings(
        reliable=reliable.ReliableSettings(**CONSTRAINTS[point.constraints]),
        n_samples=point.samples, n_trials=point.trials, subset_fraction=point.subset,
        seed=point.seed, refine=point.refine)
    t0 = time.perf_counter()
    result = pipeline.run(B, inputs, settings)
    pipeline_s = time.perf_counter() - t0
    region = result.regions[0]
    timings = {k: float(result.timings.get(k, 0.0)) for k in STAGES}
    timings["gbuffers"] = float(arrays["scan_gbuffer_s"]) * point.photos
    winner = region.winner
    table = region.table  # the fast winner's, expanded (and timed) by the pipeline
    if point.kl == "cycles":
        winner, timings["selection"] = _cycles_select(point, arrays, inputs, region.candidates)
        t0 = time.perf_counter()  # the extension expands (or refits) the Cycles winner (runner)
        if region.refine_inputs is None:
            table = region.candidates[winner]
        elif winner != region.winner:
            region.winner = winner
            pipeline.refine_chosen(region)
            table = region.table
        timings["expansion"] += time.perf_counter() - t0
    table = np.asarray(table, dtype=np.float64)
    t0 = time.perf_counter()
    fit = fitting.fit(table, errors=False)
    baked = lobes.tabulate(fit.params)
    timings["bake"] = time.perf_counter() - t0
    trial_errors = [metrics.sphere_error(np.asarray(c, np.float64), truth)
                    for c in region.candidates]
    out = {
        "point": dataclasses.asdict(point), "label": point.label(),
        "timings_s": timings, "total_s": float(sum(timings.values())),
        "pipeline_s": pipeline_s,
        "peak_rss_mb": _peak_rss_mb(),
        # other jobs share the machine: its load when this point ended
        "load_average_1_5_15_at_end": list(os.getloadavg()),
        # getrusage's max RSS survives fork + exec (it starts at the parent's peak): kept
        # for comparison only
        "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "counts": region.counts, "winner": int(winner),
        # which table the refinement kept: "trial", "energy" or "every_pixel" (None: off)
        "table": region.refinement.get("table") if region.refinement else None,
        "sphere_error": metrics.sphere_error(table, truth),
        "brdf_log_rmse": metrics.brdf_log_rmse(table, truth),
        "baked_sphere_error": metrics.sphere_error(baked, truth),
        "median_trial_sphere_error": float(np.median(trial_errors)),
        # NaN marks cells no training table measured (outside the basis), Inf never
        "no_inf": bool(not np.isinf(table).any() and not np.isinf(baked).any()),
        "nan_only_outside_basis": bool(not np.isnan(
            table.reshape(3, -1)[:, B.cells]).any()),
        "normal_error_deg": arrays["normal_error_deg"].tolist(),
    }
    return out


def _peak_rss_mb() -> float:
    """This process's own peak resident memory (VmHWM of /proc/self/status), MB."""
    peak = common.proc_status_bytes("VmHWM")
    return peak / 2**20 if peak else float("nan")


def _warm_gbuffers() -> None:
    """Every G-buffer set the points read, rendered now if not cached."""
    import capture_arrays

    for res in AXES["resolution"]:
        capture_arrays.gbuffers(resolution=res["resolution"])
    capture_arrays.gbuffers(resolution=BASE.resolution, scan_options=EXACT_SCAN)


def _read_presets() -> dict:
    from brdf_reconstruct.brdf_addon.presets import PRESETS

    return PRESETS


def _pool():
    return futures.ProcessPoolExecutor(max_workers=1, max_tasks_per_child=1,
                                       mp_context=multiprocessing.get_context("spawn"))


def _point_key(point: dict) -> str:
    return json.dumps({"refine": "none"} | point, sort_keys=True)  # as _setting


def _run_all(points, label: str, journal: pathlib.Path | None = None,
             resume: bool = False) -> list:
    """Run ``points``, one child process each, in order. Each row is also appended to
    ``journal`` (JSON lines) as it comes; with ``resume`` the rows already there for
    these points are reused instead of run again (a part stopped half way goes on
    where it stopped); without, the journal is started afresh."""
    done = {}
    if journal is not None and resume and journal.is_file():
        for line in journal.read_text().splitlines():
            try:
                row = json.loads(line)
            except json.JSONDecodeError:  # the last line of a killed run
                continue
            done[_point_key(row["point"])] = row
    elif journal is not None:
        journal.unlink(missing_ok=True)
    todo = [p for p in points if _point_key(dataclasses.asdict(p)) not in done]
    if done:
        print(f"[{label}] {len(points) - len(todo)} of {len(points)} rows from {journal}",
              flush=True)
    with _pool() as pool:
        jobs = [pool.submit(run_point, p) for p in todo]
        for i, (p, job) in enumerate(zip(todo, jobs, strict=True)):
            t0 = time.perf_counter()
            row = job.result()
            row["resumed"] = False
            done[_point_key(row["point"])] = row
            if journal is not None:
                with journal.open("a") as f:
                    f.write(json.dumps({**row, "resumed": True}) + "\n")
            print(f"[{label} {i + 1}/{len(todo)}] {p.material} seed {p.seed} {p.label()}: "
                  f"sphere {row['sphere_error']:.3f}, total {row['total_s']:.1f} s, "
                  f"{row['peak_rss_mb']:.0f} MB (waited {time.perf_counter() - t0:.0f} s)",
                  flush=True)
    return [done[_point_key(dataclasses.asdict(p))] for p in points]


def sweep_points(quick: bool) -> tuple[list, dict]:
    """Distinct points of the one-at-a-time sweep, and per axis the indices of its points."""
    points, index, axes = [], {}, {}
    materials = MATERIALS[:1] if quick else MATERIALS
    seeds = SEEDS[:1] if quick else SEEDS
    for axis, changes in AXES.items():
        if quick and axis in ("components", "kl", "resolution"):
            changes = changes[:2]
        axes[axis] = []
        for change in changes:
            config = dataclasses.replace(BASE, **change)
            axes[axis].append(config)
            for m in materials:
                for s in seeds:
                    p = dataclasses.replace(config, material=m, seed=s)
                    if p not in index:
                        index[p] = len(points)
                        points.append(p)
    return points, axes


def _setting(point: dict) -> str:
    """A point's settings without material and seed, as canonical JSON (tuples and
    lists alike), for matching rows to configurations."""
    point = {"refine": "none"} | point  # rows from before the field: no refinement
    return json.dumps({k: v for k, v in point.items() if k not in ("material", "seed")},
                      sort_keys=True)


def summarise(rows: list, configs: list) -> list:
    """Per configuration: medians over materials and seeds."""
    out = []
    for config in configs:
        key = dataclasses.asdict(config)
        mine = [r for r in rows if _setting(r["point"]) == _setting(key)]
        if not mine:
            continue
        def med(name, mine=mine):
            return float(np.median([r[name] for r in mine]))

        out.append({
            "label": config.label(), "config": key, "runs": len(mine),
            "sphere_error": med("sphere_error"), "brdf_log_rmse": med("brdf_log_rmse"),
            "baked_sphere_error": med("baked_sphere_error"),
            "median_trial_sphere_error": med("median_trial_sphere_error"),
            "total_s": med("total_s"), "peak_rss_mb": med("peak_rss_mb"),
            # rows from before the trials were kept as coefficients (2026-12-02, 43dc45d)
            # lack "expansion": their reconstruction expanded every trial's table; rows
            # from before 2026-12-04 lack "refinement" (no refit, or its time not counted)
            "timings_s": {s: float(np.median([r["timings_s"].get(s, 0.0) for r in mine]))
                          for s in STAGES},
            "per_material": {m: float(np.median([r["sphere_error"] for r in mine
                                                 if r["point"]["material"] == m]))
                             for m in sorted({r["point"]["material"] for r in mine})},
        })
    return out


def pareto(summary: list) -> list:
    """Labels of the points (on the blunted scan) no other point beats in both time and
    sphere error."""
    summary = [a for a in summary if a["config"].get("scan", "blunted") == "blunted"]
    front = []
    for a in summary:
        if not any(b["total_s"] <= a["total_s"] and b["sphere_error"] <= a["sphere_error"]
                   and (b["total_s"], b["sphere_error"]) != (a["total_s"], a["sphere_error"])
                   for b in summary):
            front.append(a["label"])
    return front


def preset_points(quick: bool) -> dict:
    """The extension's presets as points (settings from ``brdf_addon.props.PRESETS``,
    read without Blender: the same dict is in ``brdf_addon/presets.py``)."""
    with _pool() as pool:  # brdf_addon imports bpy: never in this process (_warm_gbuffers)
        presets = pool.submit(_read_presets).result()
    configs = {}
    for name, p in presets.items():
        configs[name] = dataclasses.replace(
            BASE, samples=p["samples"], trials=p["trials"], subset=p["subset_fraction"],
            kl="cycles" if p["kl_path"] == "CYCLES" else "fast", kl_samples=p["kl_samples"],
            refine="energy" if p.get("keep_highlight_energy") else "none")
    return configs


def ablation_materials(quick: bool) -> list[str]:
    """The 12 analytic held-out materials and one measured material per class
    (``testkit.measured.one_per_class``, drawn with seed 0); ``quick``: 3 and 2."""
    from brdf_reconstruct.core.brdf import database, nbrdf
    from testkit import measured

    analytic = [s["name"] for s in database.heldout_specs()]
    drawn = measured.one_per_class(nbrdf.load(measured.PACK).names)
    return analytic[:3] + drawn[:2] if quick else analytic + drawn


def run_heldout(quick: bool) -> dict:
    """Samples per trial over more materials than the sweep's four: 6 (the paper's)
    against 20 (Balanced's), both with Balanced's 16 trials and the fast selection,
    on the :func:`ablation_materials`, seed 0. Returns rows and per configuration
    the median sphere error, the materials where it is lower, and seconds."""
    materials = ablation_materials(quick)
    configs = {n: dataclasses.replace(BASE, samples=n) for n in (6, BASE.samples)}
    points = [dataclasses.replace(c, material=m, seed=0) for c in configs.values()
              for m in materials]
    rows = _run_all(points, "heldout")
    by = {n: {r["point"]["material"]: r for r in rows if r["point"]["samples"] == n}
          for n in configs}
    six, base = by[6], by[BASE.samples]
    return {"materials": materials, "rows": rows, "summary": {
        str(n): {"sphere_error_median": float(np.median([r["sphere_error"]
                                                         for r in by[n].values()])),
                 "total_s_median": float(np.median([r["total_s"] for r in by[n].values()]))}
        for n in configs} | {"6_lower_on": sum(six[m]["sphere_error"] < base[m]["sphere_error"]
                                              for m in materials)}}


def run_ablation(quick: bool, samples: int = BASE.samples) -> dict:
    """The paper's ablation on the blunted bunny, analytic and measured held-out
    materials, each with the default basis that never saw it (in-process);
    ``samples`` per trial (Balanced's 20, or the paper's 6)."""
    import capture_arrays

    from brdf_reconstruct.core.brdf import metrics
    from brdf_reconstruct.core.method import pipeline, reliable

    arrays = capture_arrays.gbuffers()
    materials = ablation_materials(quick)
    per_material = {}
    for material in materials:
        truth = common.heldout_table(material)
        B = common.default_basis_without(material)
        inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=0)
        errors = {}
        for name, options in CONSTRAINTS.items():
            settings = pipeline.PipelineSettings(
                reliable=reliable.ReliableSettings(**options), n_samples=samples,
                n_trials=BASE.trials, subset_fraction=BASE.subset, seed=0, refine="energy")
            try:
                r = pipeline.run(B, inputs, settings).regions[0]
            except ValueError as error:
                errors[name] = {"error": str(error)}
                continue
            trial = [metrics.sphere_error(np.asarray(c, np.float64), truth)
                     for c in r.candidates]
            errors[name] = {"median_trial": float(np.median(trial)),
                            "kl": float(trial[r.winner]),
                            "kl_energy": float(metrics.sphere_error(r.table, truth)),
                            "refit_skipped": r.refinement.get("skipped", ""),
                            "table": r.refinement.get("table"),
                            "reliable": r.counts.get("reliable"),
                            "skipped": r.skipped_assumptions}
        per_material[material] = errors
        print(f"[ablation] {material}: " + ", ".join(
            f"{k} {v.get('kl', float('nan')):.3f}" for k, v in errors.items()), flush=True)
    variants = [(c, path) for c in CONSTRAINTS for path in ("median_trial", "kl", "kl_energy")]
    median = {f"{c}_{path}": float(np.median([m[c][path] for m in per_material.values()
                                              if path in m[c]]))
              for c, path in variants}
    wins = sum(m["all"]["kl"] < m["none"]["median_trial"] for m in per_material.values())
    by_kind = {kind: {f"{c}_{path}": float(np.median(
        [m[c][path] for n, m in per_material.items()
         if path in m[c] and common.is_measured(n) == (kind == "measured")]))
        for c, path in variants} for kind in ("analytic", "measured")}
    return {
        "median_sphere_error": median,
        "median_sphere_error_by_kind": by_kind,
        "ratio_all_kl_to_none": median["all_kl"] / median["none_median_trial"],
        "ratio_all_kl_to_none_kl": median["all_kl"] / median["none_kl"],
        "ratio_all_kl_energy_to_none_kl_energy": (median["all_kl_energy"]
                                                  / median["none_kl_energy"]),
        "materials_where_all_kl_beats_none": f"{wins}/{len(per_material)}",
        "per_material": per_material,
        "normal_error_deg": {"median": float(arrays["normal_error_deg"][0]),
                             "p90": float(arrays["normal_error_deg"][1])},
        "settings": {"samples": samples, "trials": BASE.trials, "subset": BASE.subset,
                     "resolution": list(BASE.resolution), "photos": BASE.photos,
                     "noise": BASE.noise},
    }


def _meta(argv, args, info: dict) -> dict:
    """What a part records about its run: the command, the date, the machine (``info``,
    taken when the run started; load at the part's end added) and the invocation."""
    return {"command": " ".join([".venv/bin/python", "bench/tradeoff.py", *argv]),
            "date": datetime.date.today().isoformat(),
            "machine": common.machine_end(dict(info)),
            "invocation": common.invocation(args)}


def plot_tradeoff(report: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    colours = dict(zip(AXES, ("C0", "C1", "C2", "C3", "C4", "C5"), strict=True))
    front = set(report["pareto"])
    for axis, labels in report["axes"].items():
        pts = [s for s in report["summary"] if s["label"] in labels]
        ax.scatter([p["total_s"] for p in pts], [p["sphere_error"] for p in pts],
                   c=colours[axis], label=axis, s=28)
        for p in pts:
            ax.annotate(_short(p["label"], axis), (p["total_s"], p["sphere_error"]),
                        fontsize=6, xytext=(3, 2), textcoords="offset points")
    fr = sorted((s for s in report["summary"] if s["label"] in front),
                key=lambda s: s["total_s"])
    ax.plot([s["total_s"] for s in fr], [s["sphere_error"] for s in fr], "k--", lw=0.8,
            label="Pareto front")
    for name, s in report.get("presets", {}).items():
        ax.scatter([s["total_s"]], [s["sphere_error"]], marker="*", s=160, c="k", zorder=5)
        ax.annotate(name.title(), (s["total_s"], s["sphere_error"]), fontsize=8,
                    xytext=(5, -9), textcoords="offset points", weight="bold")
    ax.set_xscale("log")
    ax.set_xlabel("wall time per run, s (G-buffers + science + bake; log)")
    ax.set_ylabel("rendered-sphere relative RMSE (median)")
    n_measured = sum(common.is_measured(m) for m in MATERIALS)
    ax.set_title(f"Speed/accuracy on the bunny capture ({len(MATERIALS) - n_measured} "
                 f"analytic + {n_measured} measured materials, {len(SEEDS)} seeds)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _short(label: str, axis: str) -> str:
    key = {"trials": "trials=", "samples": "samples=", "resolution": "res=",
           "components": "k=", "kl": "kl=", "exact_normals": "samples="}[axis]
    return next(part for part in label.split() if part.startswith(key)) + (
        " exact" if axis == "exact_normals" else "")


def plot_ablation(report: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    med = report["median_sphere_error"]
    names = list(CONSTRAINTS)
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.bar(x - 0.27, [med[f"{n}_median_trial"] for n in names], 0.27, label="median trial")
    ax.bar(x, [med[f"{n}_kl"] for n in names], 0.27, label="KL-chosen trial")
    ax.bar(x + 0.27, [med.get(f"{n}_kl_energy", np.nan) for n in names], 0.27,
           label="KL-chosen trial + energy refit (the default)")
    ax.set_xticks(x, names)
    ax.set_ylabel("median rendered-sphere rel. RMSE")
    ax.set_title(f"Ablation on the blunted bunny ({len(report['per_material'])} held-out "
                 "materials)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--part", choices=("all", "sweep", "presets", "ablation", "summary",
                                           "heldout"),
                        default="all",
                        help="heldout (not in all): the paper's 6 samples per trial against "
                        "Balanced's 20, both 16 trials and the fast selection, over the "
                        "ablation's held-out materials, 1 seed: tradeoff_heldout.json")
    parser.add_argument("--resume", action="store_true",
                        help="--part sweep/all: reuse the rows a stopped sweep left in "
                        "bench/results/.tradeoff_sweep.jsonl (each row is written there "
                        "as it comes) and run only the rest")
    parser.add_argument("--samples", type=int, default=BASE.samples,
                        help=f"samples per trial of the ablation (default {BASE.samples}, "
                        "Balanced's; 6: the paper's mode, written to "
                        "ablation_bunny_samples6.json)")
    args = parser.parse_args(argv)
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    info = common.machine(NOTE)
    t0 = time.perf_counter()

    # Render (or find) the G-buffers once, in a child: a process that has imported bpy
    # hands its sys.path (with bpy's own scripts/modules first) to the spawned point
    # processes, whose "import bpy" then finds the inner module and fails.
    with _pool() as pool:
        pool.submit(_warm_gbuffers).result()
    tag = "_quick" if args.quick else ""
    path = RESULTS / f"tradeoff{tag}.json"
    report = json.loads(path.read_text()) if path.is_file() else {}
    if args.part in ("all", "sweep"):
        points, axes = sweep_points(args.quick)
        journal = RESULTS / f".tradeoff{tag}_sweep.jsonl"
        rows = _run_all(points, "sweep", journal, resume=args.resume)
        configs = [c for cs in axes.values() for c in cs]
        report.update(meta=_meta(argv, args, info), base=dataclasses.asdict(BASE), rows=rows,
                      summary=summarise(rows, list(dict.fromkeys(configs))),
                      axes={a: [c.label() for c in cs] for a, cs in axes.items()})
        report["pareto"] = pareto(report["summary"])
        report["meta"]["rows_resumed"] = sum(r["resumed"] for r in rows)
    if args.part == "summary":  # recompute the summaries and plot from the stored rows
        _, axes = sweep_points(args.quick)
        configs = [c for cs in axes.values() for c in cs]
        summary = summarise(report.get("rows", []), list(dict.fromkeys(configs)))
        if not summary:  # rows of another definition of a point (e.g. without "basis")
            print(f"{path}: no stored sweep row matches a configuration of the sweep; "
                  "nothing written", file=sys.stderr)
            return 1
        report.update(summary=summary, pareto=pareto(summary),
                      axes={a: [c.label() for c in cs] for a, cs in axes.items()})
        if "preset_rows" in report:  # each preset of PRESETS whose rows are stored
            presets = {}
            for name, config in preset_points(args.quick).items():
                found = summarise(report["preset_rows"], [config])
                if found:
                    presets[name] = found[0]
                else:
                    print(f"preset {name}: no stored row has its settings; run "
                          "--part presets", file=sys.stderr)
            report["presets"] = presets
    if args.part in ("all", "presets"):
        configs = preset_points(args.quick)
        points = [dataclasses.replace(c, material=m, seed=s) for c in configs.values()
                  for m in MATERIALS for s in SEEDS]
        # a preset that is a point of the sweep is not run again: its rows are reused
        def key(p):
            return _point_key(dataclasses.asdict(p))

        done = {_point_key(r["point"]): r for r in report.get("rows", [])}
        todo = [p for p in points if key(p) not in done]
        ran = {key(p): r for p, r in zip(todo, _run_all(todo, "presets"), strict=True)}
        rows = [done.get(key(p)) or ran[key(p)] for p in points]
        report["preset_rows_reused"] = len(points) - len(todo)
        summary = summarise(rows, list(configs.values()))
        report["presets"] = {name: s for name, s in zip(configs, summary, strict=True)}
        report["preset_rows"] = rows
        report["presets_meta"] = _meta(argv, args, info)
    if args.part == "heldout":
        common.write_json(RESULTS / f"tradeoff_heldout{tag}.json",
                          run_heldout(args.quick) | {"meta": _meta(argv, args, info)},
                          arguments=args)
        print(f"done in {time.perf_counter() - t0:.0f} s")
        return 0
    if args.part in ("all", "ablation"):
        ablation = run_ablation(args.quick, args.samples)
        ablation["meta"] = _meta(argv, args, info)
        stem = f"ablation_bunny{tag}" + ("" if args.samples == BASE.samples
                                          else f"_samples{args.samples}")
        common.write_json(RESULTS / f"{stem}.json", ablation, arguments=args)
        plot_ablation(ablation, RESULTS / f"{stem}.png")
        print(f"ablation: all constraints + KL / no constraints = "
              f"{ablation['ratio_all_kl_to_none']:.2f}")
    if "summary" in report and args.part != "ablation":
        common.write_json(path, report, arguments=args)
        plot_tradeoff(report, RESULTS / f"tradeoff{tag}.png")
        print(f"wrote {path}")
        if args.part in ("all", "sweep"):  # its rows are in the report now
            (RESULTS / f".tradeoff{tag}_sweep.jsonl").unlink(missing_ok=True)
    print(f"done in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
