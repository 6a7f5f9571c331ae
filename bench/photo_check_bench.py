"""The photos' check on the trials (``core.method.selection.photo_eligible``): what it
changes. Writes ``bench/results/photo_check.json``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/photo_check_bench.py             # seeds 0 and 1, about 50 minutes
    .venv/bin/python bench/photo_check_bench.py --seed 0    # one seed (about 25 minutes),
    .venv/bin/python bench/photo_check_bench.py --seed 1    # e.g. side by side on 2 cores,
    .venv/bin/python bench/photo_check_bench.py --merge     # then photo_check.json from them
    .venv/bin/python bench/photo_check_bench.py --quick     # seed 0, the bunny only

With a refit on, the pipeline chooses by KL only among the trials whose renders miss
the photos at most ``selection.MAX_RMSE_RATIO`` times the best trial's relative RMSE.
Here Balanced runs twice on each capture of ``bench/photo_bench.py`` (the bunny and
Spot, their degraded and exact scans, 240 x 180, 3 photos, 1 % noise, the 19
held-out materials, each with the default basis without it) as captured
("point") and with each photo moved half a pixel (``optics_bench.changed``, "moved
0.5", a misregistered pose, where the check was found to matter): with the check
(the pipeline as it is) and without it (``selection.photo_eligible`` replaced by
one that keeps every trial). Per run: the sphere error of both, the trials the check
excluded and the KL's own winner where it moved the choice.
"""
from __future__ import annotations

import argparse
import json
import sys

import capture_arrays
import common
import numpy as np
import optics_bench
import photo_bench

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline, selection

VARIANTS = ("point", "moved 0.5")


def _every_trial(rmse, ratio=None):
    return np.ones(len(rmse), dtype=bool)


def run_seed(seed: int, objects=("bunny", "spot")) -> list[dict]:
    rows = []
    real = selection.photo_eligible
    for obj in objects:
        captures = photo_bench.scans(obj)
        for name in common.pipeline_materials(False):
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for scan, arrays in captures.items():
                base = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
                for variant in VARIANTS:
                    inputs = (base if variant == "point"
                              else optics_bench.changed(base, variant, seed=seed))
                    settings = pipeline.PipelineSettings(seed=seed,
                                                         **photo_bench.MODES["balanced"])
                    row = dict(object=obj, material=name, scan=scan, variant=variant,
                               seed=seed)
                    try:
                        for label, check in (("with", real), ("without", _every_trial)):
                            selection.photo_eligible = check
                            r = pipeline.run(B, inputs, settings, regions=[0]).regions[0]
                            row[label] = float(metrics.sphere_error(r.table, truth))
                            row[f"{label}_table"] = r.refinement.get("table")
                            if label == "with":
                                row["excluded"] = r.selection.get("photo_excluded")
                                row["kl_winner"] = r.selection.get("kl_winner")
                                row["winner"] = int(r.winner)
                    finally:
                        selection.photo_eligible = real
                    rows.append(row)
                    print(f"{obj} {name} {scan} {variant}: {row['without']:.3f} -> "
                          f"{row['with']:.3f} excluded {row['excluded']}", flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    moved = [r for r in rows if abs(r["with"] - r["without"]) > 1e-12]
    return {"runs": len(rows),
            "with_exclusions": sum(bool(r["excluded"]) for r in rows),
            "choice_moved": len(moved),
            "changed": [{k: r[k] for k in ("object", "material", "scan", "variant", "seed",
                                           "without", "with", "kl_winner", "winner")}
                        for r in moved],
            "better": sum(r["with"] < r["without"] for r in moved),
            "worse": sum(r["with"] > r["without"] for r in moved),
            "median_without": float(np.median([r["without"] for r in rows])),
            "median_with": float(np.median([r["with"] for r in rows]))}


def _document(rows: list[dict], machines: list[dict]) -> dict:
    return {"what": "the photos' check on the trials, with and without",
            "max_rmse_ratio": selection.MAX_RMSE_RATIO, "variants": VARIANTS,
            "seeds": sorted({r["seed"] for r in rows}), "machines": machines,
            "summary": summary(rows), "runs": rows}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=None,
                        help="run this seed alone, into photo_check_seed<S>.json")
    parser.add_argument("--merge", action="store_true",
                        help="write photo_check.json from the photo_check_seed*.json files")
    parser.add_argument("--quick", action="store_true", help="seed 0, the bunny only")
    args = parser.parse_args(argv)
    if args.merge:
        parts = sorted(common.RESULTS.glob("photo_check_seed*.json"))
        if not parts:
            print("error: no photo_check_seed*.json to merge; run --seed first",
                  file=sys.stderr)
            return 1
        docs = [json.loads(p.read_text()) for p in parts]
        doc = _document([r for d in docs for r in d["runs"]], [d["machine"] for d in docs])
        path = common.write_json(common.RESULTS / "photo_check.json", doc,
                                 arguments=vars(args))
        for p in parts:
            p.unlink()
    elif args.seed is not None:
        info = common.machine("the photos' check on the trials")
        rows = run_seed(args.seed)
        doc = {"machine": common.machine_end(info), "seed": args.seed, "runs": rows,
               "summary": summary(rows)}
        path = common.write_json(common.RESULTS / f"photo_check_seed{args.seed}.json", doc,
                                 arguments=vars(args))
    else:
        info = common.machine("the photos' check on the trials")
        objects = ("bunny",) if args.quick else ("bunny", "spot")
        rows = [r for seed in ((0,) if args.quick else (0, 1))
                for r in run_seed(seed, objects)]
        doc = _document(rows, [common.machine_end(info)])
        stem = "photo_check_quick" if args.quick else "photo_check"
        path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    print(json.dumps(doc["summary"], indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
