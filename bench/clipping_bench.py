"""A highlight clipped at the camera's white level: leave the clipped pixels out (the
white level given) or use them at their clipped value (not given)?

    .venv/bin/python bench/clipping_bench.py [--seeds S] [--objects bunny,spot] [--quick]

A float photo (an EXR from a RAW converter) does not state its white level; since
2026-12-07 the extension finds a highlight clipped at one by its plateau
(``core.capture.photo_io.plateau_levels``) and says so, but leaves the pixels as they
are. This bench measures that choice. For each object (the blunted bunny and Spot of
``bench/photo_bench.py``, and each with the truth's G-buffers as the scan, "exact"),
each held-out material (the 12 analytic and one measured per class;
``--quick``: 3 and 2) and each seed, three photos with 1 % noise
(``capture_arrays.photo_inputs``) are clipped at the level where 1 % and 5 % of the
object's pixels (their largest channel) reach it, and run through Balanced
(``core.method.pipeline.run``, the photo bench's settings) twice: with
``ObservationSettings.clip_level`` at that level ("given": the clipped pixels
removed, Eq. (2) skipped, as the Saturation Level or an integer file's largest code
does) and without ("not given": the clipped values taken as they are).

Per run: the sphere error of each (``metrics.sphere_error``) and which table the
refinement kept. Summary per object, scan and share: how many runs each variant wins
by more than 0.01, the medians, and the geometric mean of given over not given.
Writes ``bench/results/clipping.json`` (``--quick``: ``clipping_quick.json``). About
25 minutes on the 2-core machine.
"""

from __future__ import annotations

import json
import sys
import time

import capture_arrays
import common
import numpy as np
import photo_bench

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import observations, pipeline

SHARES = (0.01, 0.05)  # of the object's pixels at or above the white level
SETTINGS = dict(n_samples=20, n_trials=16, refine="energy")  # Balanced, as photo_bench


def white_level(inputs, share: float) -> float:
    """The level that ``share`` of the photos' object pixels (their largest channel)
    reach: the white level of a camera exposed so that they clip."""
    values = np.concatenate([np.max(p.photo[np.asarray(p.region) >= 0], axis=-1)
                             for p in inputs])
    return float(np.quantile(values, 1.0 - share))


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials, 1 seed")
    if args is None:
        return objects
    seeds = 1 if args.quick else args.seeds
    info = common.machine("clipped highlights: the white level given or not")
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj, scan, arrays, name, truth, B in photo_bench.cases(objects, names):
        for seed in range(seeds):
            clean = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
            for share in SHARES:
                level = white_level(clean, share)
                inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01,
                                                     seed=seed, clip_level=level)
                row = dict(object=obj, scan=scan, material=name, seed=seed,
                           share=share, level=level)
                for variant, given in (("not_given", None), ("given", level)):
                    settings = pipeline.PipelineSettings(
                        seed=seed, **SETTINGS,
                        observation=observations.ObservationSettings(clip_level=given))
                    t0 = time.perf_counter()
                    region = pipeline.run(B, inputs, settings, regions=[0]).regions[0]
                    row[variant] = float(metrics.sphere_error(region.table, truth))
                    row[f"{variant}_table"] = region.refinement.get("table")
                    row[f"{variant}_saturated"] = int(region.counts.get("saturated", 0))
                    row[f"{variant}_seconds"] = time.perf_counter() - t0
                rows.append(row)
                print(f"{obj} {scan} {name} seed {seed} clipped {share:.0%}: not given "
                      f"{row['not_given']:.3f}, given {row['given']:.3f}", flush=True)
    summary = _summary(rows)
    doc = {"machine": common.machine_end(info), "materials": names, "seeds": list(range(seeds)),
           "shares": list(SHARES), "settings": SETTINGS, "summary": summary, "runs": rows}
    stem = "clipping_quick" if args.quick else "clipping"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    print(json.dumps(summary, indent=1))
    print(f"-> {path}")
    return 0


def _summary(rows) -> dict:
    """Per object, scan and share (and over both shares): runs, the wins of each
    variant by more than 0.01, the medians and the geometric mean of given / not given."""
    out = {}
    for key in sorted({(r["object"], r["scan"], r["share"]) for r in rows}) + sorted(
            {(r["object"], r["scan"], "all") for r in rows}):
        obj, scan, share = key
        sel = [r for r in rows if r["object"] == obj and r["scan"] == scan
               and (share == "all" or r["share"] == share)]
        given = np.array([r["given"] for r in sel])
        not_given = np.array([r["not_given"] for r in sel])
        out[f"{obj}/{scan}/{share}"] = {
            "runs": len(sel),
            "given_better": int(np.sum(given < not_given - 0.01)),
            "not_given_better": int(np.sum(not_given < given - 0.01)),
            "median_given": float(np.median(given)),
            "median_not_given": float(np.median(not_given)),
            "geomean_given_over_not_given": float(np.exp(np.mean(np.log(given / not_given))))}
    return out


if __name__ == "__main__":
    sys.exit(main())
