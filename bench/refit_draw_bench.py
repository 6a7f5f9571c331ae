"""The refits on large photos: every observed sample against a uniform draw of at most
``refine.MAX_REFIT_SAMPLES`` (``refine.refit_samples``).

    BRDF_RECONSTRUCT_CACHE=.cache .venv/bin/python bench/refit_draw_bench.py [--quick]

The refinement (the energy refit and the photos' judge with its held-out refits)
costs in proportion to the samples it reads. A real camera's photos hold far more
pixels than the 240 x 180 captures every other bench uses (about 18,000 observed
samples from 3 photos), so this bench runs ``core.method.pipeline.run`` (Balanced's
settings: 20 samples x 16 trials, the energy refit judged by the photos, seed 0) on
the bunny capture of ``bench/capture_arrays.py`` rendered larger (3 photos; 1 %
noise; the scan degraded, or exact normals) twice per point: reading every observed
sample (the cap lifted) and reading the draw (the default). Points: 240 x 180 (under
the cap: the same run twice), 960 x 720 (three held-out materials: gold, the silver
mirror, the glossy plastic; both scans) and 1920 x 1440 (the gold, exact normals).
Each run is its own process: ``peak_gib`` is its high-water mark (``VmHWM``). Per
run: the refinement's seconds and the whole run's, the samples read, the sphere
error (``metrics.sphere_error`` through ``photo_bench._scores``) and which table the
refinement kept. Writes ``bench/results/refit_draw.json`` (``--quick``: 240 and 960
only, the gold, ``refit_draw_quick.json``). About 15 minutes on the 2-core machine
(the G-buffers of the larger captures are rendered once and cached, about 1 minute).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import common

POINTS = [((240, 180), "heldout_gold_medium", "exact")]
POINTS += [((960, 720), m, s) for m in ("heldout_gold_medium", "heldout_silver_mirror",
                                         "heldout_glossy_plastic") for s in ("exact", "scan")]
POINTS += [((1920, 1440), "heldout_gold_medium", "exact")]
CAPS = ("all", "draw")  # every observed sample; refine.MAX_REFIT_SAMPLES (the default)


def child(point: dict) -> dict:
    """One pipeline run in this process (``point``: resolution, material, scan, cap)."""
    import capture_arrays
    import photo_bench

    from brdf_reconstruct.core.method import pipeline, refine

    if point["cap"] == "all":
        refine.MAX_REFIT_SAMPLES = 10**12
    arrays = capture_arrays.gbuffers(resolution=tuple(point["resolution"]))
    if point["scan"] == "exact":
        arrays = photo_bench.exact_scan(arrays)
    truth = common.heldout_table(point["material"])
    basis = common.default_basis_without(point["material"])
    inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=0)
    settings = pipeline.PipelineSettings(seed=0, **photo_bench.MODES["balanced"])
    t0 = time.perf_counter()
    region = pipeline.run(basis, inputs, settings, regions=[0]).regions[0]
    run_s = time.perf_counter() - t0
    return dict(point, run_s=run_s, refinement_s=float(region.timings["refinement"]),
                observed=int(region.counts["observed"]), read=int(region.counts["refit"]),
                trusted_read=int(region.counts["refit_trusted"]),
                reliable=int(region.counts["reliable"]), table=region.refinement["table"],
                sphere=photo_bench._scores(region.table, truth, arrays, inputs)["sphere"],
                peak_gib=common.proc_status_bytes("VmHWM") / common.GIB)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="240 x 180 and 960 x 720, the gold only; refit_draw_quick.*")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(json.loads(args.child))), flush=True)
        return 0
    info = common.machine("the refits on large photos: every sample or a uniform draw")
    points = [p for p in POINTS if not args.quick
              or (p[0][0] <= 960 and p[1] == "heldout_gold_medium")]
    rows = []
    for (w, h), material, scan in points:
        for cap in CAPS:
            point = {"resolution": [w, h], "material": material, "scan": scan, "cap": cap}
            done = subprocess.run([sys.executable, __file__, "--child", json.dumps(point)],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                print(done.stderr[-2000:], file=sys.stderr)
                return 1
            row = json.loads(done.stdout.strip().splitlines()[-1])
            rows.append(row)
            print(f"{w}x{h} {material} {scan} {cap}: read {row['read']} of "
                  f"{row['observed']}, refinement {row['refinement_s']:.1f} s, run "
                  f"{row['run_s']:.1f} s, peak {row['peak_gib']:.2f} GiB, sphere "
                  f"{row['sphere']:.4f} ({row['table']})", flush=True)
    doc = {"machine": common.machine_end(info), "settings": "Balanced (20 x 16, energy "
           "refit judged by the photos), seed 0, 3 photos, 1 % noise", "runs": rows}
    stem = "refit_draw_quick" if args.quick else "refit_draw"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
