"""Choose one trial by KL, or average the trials? Measured, not adopted (issue 15).
Writes ``bench/results/trial_combination.json`` and ``trial_combination.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/trial_combination_bench.py            # about 30 minutes
    .venv/bin/python bench/trial_combination_bench.py --quick    # 5 materials, 1 seed

Balanced draws 16 trials (20 condition-optimal samples each), keeps the one whose
fast KL is lowest and refits it to the photos' energy (``pipeline.refine_chosen``).
Issue 15 asks for a selection that does not hang on the seed. This bench scores,
from one Balanced run per material, scan and seed:

- ``chosen``: Balanced as it is (the lowest-KL trial, refitted);
- ``mean``: the mean of the 16 trials' basis coefficients (the mapped, log-relative
  space; bagging), refitted the same way;
- ``median``: their element-wise median, refitted;
- ``mean_top_half``: the mean of the 8 trials with the lowest KL, refitted (the KL
  as a guard against trials that fit the samples but not the photos).

The combined reconstruction keeps the lowest-KL trial's regulariser and
condition number, which the refit only reports. Scenes and scoring are
``bench/photo_bench.py``'s: the degraded bunny (3 seeds) and Spot (1 seed), and the
bunny's exact scan (1 seed) as the floor; the 12 analytic and 7 measured held-out
materials, each with the default basis without it; 3 photos, 1 % noise. Per row
the rendered-sphere error; the summary gives per scan the median over materials
(of the median over seeds), the seed spread, and per variant against ``chosen``
the geometric-mean ratio and how many materials are better / worse by 1 %.
"""
from __future__ import annotations

import dataclasses
import sys
import time

import capture_arrays
import common
import numpy as np
import photo_bench

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline
from testkit import measured

VARIANTS = ("chosen", "mean", "median", "mean_top_half")
# (object, scan, seeds): the bunny's degraded scan over --seeds (3: the seed spread),
# Spot's on one, and the bunny's exact scan (the floor) on one
CASES = (("bunny", "scan", None), ("spot", "scan", 1), ("bunny", "exact", 1))


def combined(region, coefficients):
    """The region's table refitted from ``coefficients`` (p, 3) as Balanced refits
    its chosen trial: a Reconstruction like the lowest-KL trial's with these
    coefficients, refitted by ``pipeline.refine_chosen``; the region is left as
    it was."""
    recs = region.candidates.reconstructions
    best = int(np.argmin(region.kl))
    recs.append(dataclasses.replace(recs[best], coefficients=coefficients))
    saved = (region.winner, region.table, region.refinement, dict(region.timings))
    region.winner = len(recs) - 1
    try:
        pipeline.refine_chosen(region)
        return region.table
    finally:
        recs.pop()
        region.winner, region.table, region.refinement, region.timings = saved


def variants(region) -> dict:
    """Per variant (``VARIANTS``) the region's (3, 90, 90, 180) table."""
    recs = region.candidates.reconstructions
    p = max(r.coefficients.shape[0] for r in recs)
    coefs = np.stack([np.pad(r.coefficients, ((0, p - r.coefficients.shape[0]), (0, 0)))
                      for r in recs])
    order = np.argsort(region.kl)
    return {"chosen": region.table,
            "mean": combined(region, coefs.mean(axis=0)),
            "median": combined(region, np.median(coefs, axis=0)),
            "mean_top_half": combined(region, coefs[order[: max(len(recs) // 2, 1)]].mean(axis=0))}


def summary(rows: list) -> dict:
    out = {}
    for obj, scan, _ in CASES:
        part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
        if not part:
            continue
        names = sorted({r["material"] for r in part})
        per = {v: {n: [r["sphere"][v] for r in part if r["material"] == n] for n in names}
               for v in VARIANTS}
        entry = {}
        for v in VARIANTS:
            med = {n: float(np.median(x)) for n, x in per[v].items()}
            ratio = np.array([np.log(a / b) for n in names
                              for a, b in zip(per[v][n], per["chosen"][n], strict=True)])
            entry[v] = {
                "median": float(np.median(list(med.values()))),
                "seed_spread": float(np.median([(max(x) - min(x)) / np.median(x)
                                                for x in per[v].values()])),
                "geometric_mean_ratio_to_chosen": float(np.exp(ratio.mean())),
                "better": int(np.sum(ratio < -0.01)), "worse": int(np.sum(ratio > 0.01)),
                "runs": int(len(ratio))}
        out[f"{obj}/{scan}"] = entry
    return out


def plot(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in CASES if any(r["object"] == c[0] and r["scan"] == c[1] for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(5 * len(cases), 4.5), squeeze=False)
    for ax, (obj, scan, _) in zip(axes[0], cases, strict=True):
        part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
        chosen = np.array([r["sphere"]["chosen"] for r in part])
        for v, marker in zip(VARIANTS[1:], "o^s", strict=True):
            ax.scatter(chosen, [r["sphere"][v] for r in part], s=14, marker=marker, label=v)
        lim = [0.9 * chosen.min(), 1.1 * max(chosen.max(), 1e-3)]
        ax.plot(lim, lim, "k:", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("chosen by KL, refitted (sphere error)")
        ax.set_ylabel("combined trials, refitted")
        ax.set_title(f"{obj}, {scan}: one point per material and seed", fontsize=9)
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 3, "5 materials, 1 seed")
    if args is None:
        return objects
    info = common.machine("choosing one trial by KL or combining the trials, issue 15")
    t0 = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj, scan, seeds in CASES:
        if obj not in objects:
            continue
        arrays = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                         else measured.DATA / "spot.obj")
        if scan == "exact":
            arrays = photo_bench.exact_scan(arrays)
        for name in names:
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for seed in range(1 if args.quick else seeds or args.seeds):
                inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
                region = pipeline.run(B, inputs, pipeline.PipelineSettings(seed=seed),
                                      regions=[0]).regions[0]
                if region.status != "ok":
                    print(f"{obj} {scan} {name} seed {seed}: {region.reason}", flush=True)
                    continue
                sphere = {v: metrics.sphere_error(t, truth) for v, t in variants(region).items()}
                rows.append({"object": obj, "scan": scan, "material": name, "seed": seed,
                             "measured": common.is_measured(name), "sphere": sphere})
                print(f"{obj} {scan} {name} seed {seed}: " + ", ".join(
                    f"{v} {e:.3f}" for v, e in sphere.items()), flush=True)
    doc = {"machine": common.machine_end(info), "materials": names,
           "settings": "Balanced (PipelineSettings() defaults), 3 photos, 1 % noise",
           "cases": [list(c) for c in CASES], "minutes": (time.perf_counter() - t0) / 60.0,
           "summary": summary(rows), "runs": rows}
    stem = "trial_combination_quick" if args.quick else "trial_combination"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(rows, path.with_suffix(".png"))
    for case, entry in doc["summary"].items():
        print(case, {v: round(e["median"], 3) for v, e in entry.items()})
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
