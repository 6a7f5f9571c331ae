"""Two ideas for the photo-consistency refit, measured (issue 15): a KL guard on it,
and a radiance model that knows the scan's normals are wrong.

    .venv/bin/python bench/refit_bench.py [--seeds S] [--objects bunny,spot]
                                          [--sigmas 3] [--quick]

The capture is ``bench/photo_bench.py``'s: the blunted bunny and Spot (and each with
the truth's G-buffers, "exact"), three photos with 1 % noise, the 12 analytic
held-out materials and one measured material per class, the default basis without
the material. Each run is Balanced with the refit on (``refine="photo"``); per run:

- ``plain``: the chosen trial, as Balanced gives it;
- ``refit``: the pipeline's refit of it (``refine.photo_consistent``);
- ``kl_guard``: the refit kept only if its fast KL against the photos
  (``selection.select_by_kl`` over the region's views) is below the trial's,
  else the trial;
- ``sigma_<d>``: the refit with ``normal_sigma`` = d degrees, the radiance of a
  pixel predicted as the mean over 8 normals drawn about the scan's (on the exact
  scan too, where the right value is 0: what a wrong guess costs).

Each with its rendered-sphere error (``metrics.sphere_error``). Summaries per
object and scan: the median over materials of each variant's median over seeds,
and for the guard how often it kept the better of the two. Writes
``bench/results/refit.json`` and ``refit.png`` (``--quick``: ``refit_quick.*``).
About 25 minutes for 1 seed on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import capture_arrays
import common
import numpy as np
import photo_bench

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline, refine, selection


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--objects", default="bunny,spot")
    parser.add_argument("--sigmas", default="3", help="comma-separated degrees, > 0")
    parser.add_argument("--quick", action="store_true", help="3 + 2 materials, bunny only")
    args = parser.parse_args(argv)
    objects = common.listed(args.objects, ("bunny", "spot"), "--objects")
    try:
        sigmas = [float(s) for s in args.sigmas.split(",")]
    except ValueError:
        sigmas = []
    if objects is None:
        return 2
    if not sigmas or min(sigmas) <= 0 or args.seeds < 1:
        print("error: --sigmas must be positive degrees and --seeds at least 1",
              file=sys.stderr)
        return 2
    if args.quick:
        objects = ["bunny"]
    info = common.machine("the refit's KL guard and normal-error model, issue 15")
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj, scan, arrays, name, truth, B in photo_bench.cases(objects, names):
        for seed in range(args.seeds):
            row = _run(arrays, truth, B, seed, sigmas)
            rows.append(dict(object=obj, scan=scan, material=name, seed=seed,
                             measured=common.is_measured(name), **row))
            print(f"{obj} {scan} {name} {seed}: " + ", ".join(
                f"{k} {v:.3f}" for k, v in row["sphere"].items()), flush=True)
    summary = _summary(rows)
    doc = {"machine": common.machine_end(info), "materials": names,
           "seeds": list(range(args.seeds)), "sigmas_deg": sigmas,
           "settings": "Balanced (20 x 16, fast KL) with refine='photo'; 3 photos, 1 % noise",
           "summary": summary, "runs": rows}
    stem = "refit_quick" if args.quick else "refit"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(doc, path.with_suffix(".png"))
    print(json.dumps(summary, indent=1))
    print(f"-> {path}")
    return 0


def _run(arrays, truth, B, seed, sigmas) -> dict:
    """Sphere errors of the variants (module docstring) for one material and seed."""
    inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
    settings = pipeline.PipelineSettings(seed=seed, n_samples=20, n_trials=16, refine="photo")
    region = pipeline.run(B, inputs, settings, regions=[0]).regions[0]
    inp = region.refine_inputs
    basis, observed, trusted = inp.basis, inp.observed, inp.trusted
    start = region.candidates.reconstructions[region.winner]
    # the trial's KL is the selection's (the bins depend on the photos alone); the
    # refit is the pipeline's own (region.table), scored on the same views
    kl = [float(region.kl[region.winner]),
          float(selection.select_by_kl([region.table], pipeline.region_views(inputs, 0)).kl[0])]
    sphere = {"plain": metrics.sphere_error(start.expand(), truth),
              "refit": metrics.sphere_error(region.table, truth)}
    sphere["kl_guard"] = sphere["refit"] if kl[1] < kl[0] else sphere["plain"]
    seconds = {}
    for d in sigmas:
        t0 = time.perf_counter()
        blurred = refine.photo_consistent(basis, start, observed, trusted,
                                          normal_sigma=np.radians(d))
        seconds[f"sigma_{d:g}"] = time.perf_counter() - t0
        sphere[f"sigma_{d:g}"] = metrics.sphere_error(blurred.table, truth)
    return {"sphere": {k: float(v) for k, v in sphere.items()},
            "kl": kl, "seconds": seconds}


def _summary(rows) -> dict:
    out = {}
    for key in sorted({(r["object"], r["scan"]) for r in rows}):
        part = [r for r in rows if (r["object"], r["scan"]) == key]
        variants = list(part[0]["sphere"])
        per = {v: {} for v in variants}
        for r in part:
            for v in variants:
                per[v].setdefault(r["material"], []).append(r["sphere"][v])
        med = {v: float(np.median([np.median(x) for x in per[v].values()])) for v in variants}
        right = sum((r["kl"][1] < r["kl"][0]) == (r["sphere"]["refit"] < r["sphere"]["plain"])
                    for r in part)
        out["/".join(key)] = {"median_sphere": med, "guard_kept_the_better": right,
                              "runs": len(part)}
    return out


def plot(doc: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = doc["summary"]
    keys = list(summary)
    variants = list(next(iter(summary.values()))["median_sphere"])
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / len(variants)
    for i, v in enumerate(variants):
        ax.bar(np.arange(len(keys)) + i * width, [summary[k]["median_sphere"][v] for k in keys],
               width, label=v)
    ax.set_xticks(np.arange(len(keys)) + 0.4 - width / 2, keys)
    ax.set_ylabel("median sphere error")
    ax.set_title("the refit's variants (bench/refit_bench.py)")
    ax.legend(fontsize=8)
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
