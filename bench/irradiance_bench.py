"""What a wrong irradiance costs, and when the photos refuse the albedo bound.
Writes ``bench/results/irradiance.json`` and ``irradiance.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/irradiance_bench.py            # about 25 minutes
    .venv/bin/python bench/irradiance_bench.py --quick    # 5 materials

The table's level is the photos' radiance over the irradiance the user gives
(W/m^2, default 1 in the photos' own units). Given ``k`` times too little, the
photos imply ``k`` times the true table, and that is what the run should return:
every row is scored against ``k`` x the truth. On untextured photos the every-pixel
refits are bounded to reflect at most ``refine.ALBEDO_BOUND`` (1) of the light; a
surface ``k`` times too bright can need more, and the photos may refuse the bound
(``refine.BOUND_PRESSED``; the run then warns that the irradiance is likely too
low). Per object (the bunny and Spot of ``bench/photo_bench.py``), scan (degraded
and exact), material (the 12 analytic and 7 measured held-out ones, each with the
default basis without it) and ``k`` (``SCALES``), Balanced at seed 0 with 3 photos
and 1 % noise:

- ``shipped``: the pipeline as it is (the photos may refuse the bound);
- ``held`` (only where ``k`` > 1): the bound never refused (``BOUND_PRESSED`` set
  to infinity for the run), the rule's counterfactual.

Per row the rendered-sphere error against ``k`` x the truth, which table was kept,
whether the bound was refused and the true table's largest directional albedo
times ``k``. The summary gives per case and ``k`` the median over materials, the
geometric-mean ratio to ``k`` = 1 (a scale-free method gives 1), the runs that
refused the bound (at ``k`` <= 1 each is a false warning), and the shipped rule
against the bound held.
"""
from __future__ import annotations

import dataclasses
import time

import capture_arrays
import common
import numpy as np
import photo_bench

from brdf_reconstruct.core.brdf import energy, metrics
from brdf_reconstruct.core.method import pipeline, refine

SCALES = (0.25, 1.0, 2.0, 4.0)  # the irradiance given is the true one over k
SCANS = ("scan", "exact")
SEED = 0


def run_once(B, inputs, held: bool):
    """One Balanced run of ``inputs`` (region 0); ``held``: the albedo bound never
    refused (``refine.BOUND_PRESSED`` = inf for the run, restored after)."""
    pressed = refine.BOUND_PRESSED
    refine.BOUND_PRESSED = np.inf if held else pressed
    try:
        return pipeline.run(B, inputs, pipeline.PipelineSettings(seed=SEED),
                            regions=[0]).regions[0]
    finally:
        refine.BOUND_PRESSED = pressed


def row(region, truth, k) -> dict:
    """A run's scores; ``refused``: the photos refused the albedo bound (its only
    refinement notes, ``pipeline.refinement_notes``, say so)."""
    notes = pipeline.refinement_notes(region.refinement)
    return {"sphere": metrics.sphere_error(region.table, k * truth),
            "table": region.refinement.get("table"), "refused": bool(notes), "notes": notes}


def summary(rows: list) -> dict:
    out = {}
    for obj in sorted({r["object"] for r in rows}):
        for scan in SCANS:
            part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
            if not part:
                continue
            base = {r["material"]: r["shipped"]["sphere"] for r in part if r["k"] == 1.0}
            entry = {}
            for k in SCALES:
                at = [r for r in part if r["k"] == k]
                shipped = np.array([r["shipped"]["sphere"] for r in at])
                e = {"median": float(np.median(shipped)),
                     "geometric_mean_ratio_to_k1": float(np.exp(np.mean(
                         [np.log(r["shipped"]["sphere"] / base[r["material"]]) for r in at]))),
                     "refused": [r["material"] for r in at if r["shipped"]["refused"]],
                     "over_bound": [r["material"] for r in at
                                    if r["true_albedo"] > refine.ALBEDO_BOUND]}
                if at and "held" in at[0]:
                    held = np.array([r["held"]["sphere"] for r in at])
                    ratio = np.log(shipped / held)
                    e |= {"held_median": float(np.median(held)),
                          "shipped_over_held_geometric_mean": float(np.exp(ratio.mean())),
                          "better": int(np.sum(ratio < -0.01)), "worse": int(np.sum(ratio > 0.01))}
                entry[f"k={k:g}"] = e
            out[f"{obj}/{scan}"] = entry
    return out


def plot(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [(o, s) for o in sorted({r["object"] for r in rows}) for s in SCANS
             if any(r["object"] == o and r["scan"] == s for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 4), squeeze=False)
    for ax, (obj, scan) in zip(axes[0], cases, strict=True):
        part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
        for key, style in (("shipped", "o-"), ("held", "s--")):
            ks = [k for k in SCALES if any(key in r for r in part if r["k"] == k)]
            med = [np.median([r[key]["sphere"] for r in part if r["k"] == k]) for k in ks]
            ax.plot(ks, med, style, label=f"{key} (median)")
        for r in part:
            ax.scatter(r["k"], r["shipped"]["sphere"], s=6, alpha=0.35,
                       c="r" if r["shipped"]["refused"] else "0.5")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(SCALES, [f"{k:g}" for k in SCALES])
        ax.set_xlabel("true irradiance / given (k)")
        ax.set_ylabel("sphere error against k x truth")
        ax.set_title(f"{obj}, {scan} (red: refused the bound)", fontsize=9)
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials")
    if args is None:
        return objects
    info = common.machine("a wrong irradiance and the albedo bound's refusal, issue 15")
    t0 = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj, scan, arrays, name, truth, B in photo_bench.cases(objects, names):
        photos = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=SEED)
        albedo = energy.largest_albedo(truth)
        for k in SCALES:
            inputs = [dataclasses.replace(p, irradiance=np.asarray(p.irradiance) / k)
                      for p in photos]
            r = {"object": obj, "scan": scan, "material": name, "k": k,
                 "measured": common.is_measured(name), "true_albedo": k * albedo,
                 "shipped": row(run_once(B, inputs, held=False), truth, k)}
            if k > 1.0:
                r["held"] = row(run_once(B, inputs, held=True), truth, k)
            rows.append(r)
            print(f"{obj} {scan} {name} k={k:g} (albedo {k * albedo:.2f}): shipped "
                  f"{r['shipped']['sphere']:.3f}"
                  + (" refused" if r["shipped"]["refused"] else "")
                  + (f", held {r['held']['sphere']:.3f}" if "held" in r else ""),
                  flush=True)
    doc = {"machine": common.machine_end(info), "materials": names, "scales": list(SCALES),
           "settings": f"Balanced (PipelineSettings(seed={SEED})), 3 photos, 1 % noise, "
                       "the irradiance given divided by k, scored against k x truth",
           "albedo_bound": refine.ALBEDO_BOUND, "bound_pressed": refine.BOUND_PRESSED,
           "minutes": (time.perf_counter() - t0) / 60.0, "summary": summary(rows), "runs": rows}
    stem = "irradiance_quick" if args.quick else "irradiance"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(rows, path.with_suffix(".png"))
    for case, entry in doc["summary"].items():
        print(case, {k: (round(e["median"], 3), len(e["refused"])) for k, e in entry.items()})
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
