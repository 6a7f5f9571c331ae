"""Which sampler in the photo pipeline: the Bayes-risk cells against the paper's
condition-optimal cells (the pipeline's default), on two degraded scans.

    .venv/bin/python bench/sampler_bench.py [--seeds S] [--objects bunny,spot] [--quick]

For each object (the blunted bunny capture of ``testkit/capture.py`` and Spot
degraded the same way; ``capture_arrays.gbuffers``, cached) and each held-out
material (the 12 analytic ones and one measured material per class,
``testkit.measured.one_per_class``; ``--quick``: 3 and 2), three photos of the
material's table shaded on the true geometry with 1 % noise
(``capture_arrays.photo_inputs``) go through ``core.method.pipeline.run`` with
the Balanced preset's settings (the pipeline's defaults: 20 samples x 16 trials,
the fast KL), once per ``PipelineSettings.sampler``. The basis is the shipped
default that never saw the material (``common.default_basis_without``).

Scores (``metrics.sphere_error``, three evaluation lights): the KL-chosen trial
("chosen", what the user gets) and the median over the 16 trials ("trial
median", the sampler without the selection); and the wall seconds of the cell
choice (``timings["sampling"]``). Writes ``bench/results/sampler.json`` and
``sampler.png`` (``--quick``: ``sampler_quick.*``). About 15 minutes an object
and seed on the 2-core machine.
"""

from __future__ import annotations

import json
import sys
import time

import capture_arrays
import common
import numpy as np

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline, sampling
from testkit import measured


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials")
    if args is None:
        return objects
    info = common.machine("the sampler in the photo pipeline")
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj in objects:
        arrays = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                         else measured.DATA / "spot.obj")
        for name in names:
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for seed in range(args.seeds):
                inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
                for sampler in sampling.CRITERIA:
                    rows.append(_run(obj, name, seed, sampler, B, inputs, truth))
                pair = rows[-2:]
                print(f"{obj} {name} seed {seed}: " + ", ".join(
                    f"{r['sampler']} {r['chosen']:.3f} ({r['sampling_seconds']:.1f} s)"
                    for r in pair), flush=True)
    summary = _summary(rows, objects)
    doc = {"machine": common.machine_end(info), "materials": names,
           "seeds": list(range(args.seeds)),
           "settings": "pipeline defaults (the Balanced preset), 3 photos, 1 % noise",
           "summary": summary, "runs": rows}
    stem = "sampler_quick" if args.quick else "sampler"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(doc, path.with_suffix(".png"))
    print(json.dumps(summary, indent=1))
    print(f"-> {path}")
    return 0


def _run(obj, name, seed, sampler, B, inputs, truth) -> dict:
    settings = pipeline.PipelineSettings(seed=seed, sampler=sampler)
    t0 = time.perf_counter()
    region = pipeline.run(B, inputs, settings).regions[0]
    seconds = time.perf_counter() - t0
    errors = []
    for candidate in region.candidates:
        table = np.asarray(candidate, dtype=np.float64)
        if not np.all(np.isfinite(table[np.isfinite(truth)])):
            raise AssertionError(f"{obj}, {name}, {sampler}: a table holds NaN or Inf")
        errors.append(metrics.sphere_error(table, truth))
    return {"object": obj, "material": name, "measured": common.is_measured(name),
            "seed": seed, "sampler": sampler, "chosen": float(errors[region.winner]),
            "trial_median": float(np.median(errors)), "trials": [float(e) for e in errors],
            "sampling_seconds": float(region.timings.get("sampling", np.nan)),
            "seconds": seconds}


def _summary(rows, objects) -> dict:
    """Per object and kind (all, analytic, measured) and sampler: medians of the chosen
    and the trial-median errors, the share of (material, seed) pairs where the risk
    sampler's chosen trial is better, and the median seconds of the cell choice."""
    out = {}
    for obj in objects:
        out[obj] = {}
        for kind in ("all", "analytic", "measured"):
            mine = [r for r in rows if r["object"] == obj
                    and (kind == "all" or r["measured"] == (kind == "measured"))]
            entry = {s: {key: float(np.median([r[key] for r in mine if r["sampler"] == s]))
                         for key in ("chosen", "trial_median", "sampling_seconds")}
                     for s in sampling.CRITERIA}
            risk = {(r["material"], r["seed"]): r["chosen"] for r in mine
                    if r["sampler"] == "risk"}
            cond = {(r["material"], r["seed"]): r["chosen"] for r in mine
                    if r["sampler"] == "condition"}
            entry["risk_better_share"] = float(np.mean([risk[k] < cond[k] for k in risk]))
            entry["pairs"] = len(risk)
            out[obj][kind] = entry
    return out


def plot(doc: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objects = list(doc["summary"])
    fig, axes = plt.subplots(1, len(objects), figsize=(6 * len(objects), 5), squeeze=False)
    for ax, obj in zip(axes[0], objects, strict=True):
        runs = [r for r in doc["runs"] if r["object"] == obj]
        cond = {(r["material"], r["seed"]): r["chosen"] for r in runs
                if r["sampler"] == "condition"}
        for measured_kind, marker in ((False, "o"), (True, "s")):
            pts = [(cond[(r["material"], r["seed"])], r["chosen"]) for r in runs
                   if r["sampler"] == "risk" and r["measured"] == measured_kind]
            if pts:
                x, y = np.array(pts).T
                ax.scatter(x, y, marker=marker,
                           label="measured" if measured_kind else "analytic")
        lim = [min(min(cond.values()), 0.01), max(max(r["chosen"] for r in runs), 1.0)]
        ax.plot(lim, lim, "k-", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("sphere error, condition-optimal cells (the paper's, the default)")
        ax.set_ylabel("sphere error, Bayes-risk cells")
        ax.set_title(f"{obj}: KL-chosen trial per material and seed (below the line: "
                     "risk better)", fontsize=9)
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
