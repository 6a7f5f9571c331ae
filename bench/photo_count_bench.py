"""Does the error fall as lit photos are added? Writes ``bench/results/photo_count.json``
and ``photo_count.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/photo_count_bench.py            # about an hour on 2 shared cores
    .venv/bin/python bench/photo_count_bench.py --quick    # the bunny, 2 materials, 1 seed

Issue 15 found that on a real capture the paper's design did not improve as photos
were added (2, 4, 8, 16 photos: no trend): each trial reads 20 to 32 samples of
the photos' pixels, however many there are. Here the bunny and Spot are captured by
a ring of 16 cameras (``capture_arrays.gbuffers(n_views=16)``, 240 x 180, the
capture's one distant light), every camera taking a lit photo (1 % noise), and
the pipeline gets 1, 2, 4, 8 or 16 of them, evenly spread over the ring and nested
(each set holds the smaller ones: views 0; 0, 8; 0, 4, 8, 12; ...). Each run is
scored on the degraded scan and on the exact one (the truth's G-buffers: the
floor), with Balanced (``photo_bench.MODES``) and the paper's mode (6 samples x 16
trials + KL), for 6 held-out materials (``footprint_bench.default_materials``: a
metal, a plastic and a fabric, analytic and measured, each with the default basis
without it) and 3 seeds.

Per run: the sphere error (``metrics.sphere_error``, three evaluation lights), the
reliable samples, which table the refinement kept and the seconds. Summary per
(object, scan, mode, photos): the median sphere error over materials and seeds,
and against 2 photos the geometric mean of the per-run ratio and how many runs got
better or worse.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import capture_arrays
import common
import footprint_bench
import numpy as np
import photo_bench

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline

N_VIEWS = 16
COUNTS = (1, 2, 4, 8, 16)
MODES = ("balanced", "paper")
OBJECTS = ("bunny", "spot")


def views_of(count: int) -> list[int]:
    """``count`` lit views evenly spread over the ring of ``N_VIEWS``, nested."""
    return sorted({int(round(i * N_VIEWS / count)) % N_VIEWS for i in range(count)})


def captures(obj: str) -> dict:
    """{"degraded": arrays, "exact": arrays}: the object's 16-view capture
    (``photo_bench.scans`` with every camera lit)."""
    both = photo_bench.scans(obj, n_views=N_VIEWS, lit_views=tuple(range(N_VIEWS)))
    return {"degraded": both["scan"], "exact": both["exact"]}


def run(objects, materials, seeds) -> list[dict]:
    rows = []
    for obj in objects:
        scans = captures(obj)
        for name in materials:
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for seed in seeds:
                for scan, arrays in scans.items():
                    every = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
                    for count in COUNTS:
                        inputs = [every[i] for i in views_of(count)]
                        for mode in MODES:
                            settings = pipeline.PipelineSettings(seed=seed,
                                                                 **photo_bench.MODES[mode])
                            t0 = time.perf_counter()
                            try:
                                r = pipeline.run(B, inputs, settings, regions=[0]).regions[0]
                            except ValueError as error:  # e.g. no reliable pixel at all
                                r = None
                                reason = str(error)
                            if r is None or r.table is None:  # refused or skipped
                                rows.append(dict(object=obj, material=name, seed=seed,
                                                 scan=scan, photos=count, mode=mode,
                                                 sphere=None,
                                                 error=reason if r is None else r.reason))
                                continue
                            rows.append(dict(
                                object=obj, material=name, seed=seed, scan=scan,
                                photos=count, mode=mode,
                                sphere=float(metrics.sphere_error(r.table, truth)),
                                reliable=int(r.counts.get("reliable", 0)),
                                table=r.refinement.get("table"),
                                seconds=time.perf_counter() - t0))
                    print(f"{obj} {name} seed {seed} {scan}: " + ", ".join(
                        f"{r['mode'][0]}{r['photos']} "
                        + ("-" if r["sphere"] is None else f"{r['sphere']:.3f}")
                        for r in rows[-len(COUNTS) * len(MODES):]), flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    out = {}
    keys = sorted({(r["object"], r["scan"], r["mode"]) for r in rows})
    for obj, scan, mode in keys:
        mine = [r for r in rows if (r["object"], r["scan"], r["mode"]) == (obj, scan, mode)]
        by_run = {(r["material"], r["seed"], r["photos"]): r["sphere"] for r in mine}
        entry = {}
        for count in COUNTS:
            values = [r["sphere"] for r in mine if r["photos"] == count
                      and r["sphere"] is not None]
            pairs = [(by_run.get((m, s, 2)), v) for (m, s, c), v in by_run.items()
                     if c == count]
            pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
            entry[str(count)] = {
                "median": float(np.median(values)) if values else None,
                "runs": len(values),
                "geomean_vs_2": (float(np.exp(np.mean([np.log(b / a) for a, b in pairs])))
                                 if pairs else None),
                "better_than_2": sum(b < a - 0.005 for a, b in pairs),
                "worse_than_2": sum(b > a + 0.005 for a, b in pairs)}
        out[f"{obj}/{scan}/{mode}"] = entry
    return out


def plot(doc: dict, path) -> None:
    """One panel per object: median sphere error against the number of photos, per
    scan and mode (log-log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objects = [o for o in OBJECTS if any(k.startswith(o + "/") for k in doc["summary"])]
    fig, axes = plt.subplots(1, len(objects), figsize=(5.5 * len(objects), 4.2),
                             squeeze=False)
    styles = {("degraded", "balanced"): ("#404040", "-"), ("degraded", "paper"): ("#404040", ":"),
              ("exact", "balanced"): ("#2171b5", "-"), ("exact", "paper"): ("#2171b5", ":")}
    for ax, obj in zip(axes[0], objects, strict=True):
        for (scan, mode), (colour, line) in styles.items():
            entry = doc["summary"].get(f"{obj}/{scan}/{mode}")
            if not entry:
                continue
            counts = [int(c) for c in entry if entry[c]["median"] is not None]
            ax.plot(counts, [entry[str(c)]["median"] for c in counts], line, color=colour,
                    marker="o", label=f"{scan} scan, {mode}")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(list(COUNTS), [str(c) for c in COUNTS])
        ax.set_xlabel("lit photos (of a ring of 16 cameras)")
        ax.set_ylabel("median sphere error")
        ax.set_title(f"{obj}: {len(doc['materials'])} materials x {len(doc['seeds'])} seeds",
                     fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="the bunny, 2 materials, seed 0")
    args = parser.parse_args(argv)
    info = common.machine("the error against the number of lit photos")
    objects = ("bunny",) if args.quick else OBJECTS
    materials = footprint_bench.default_materials(args.quick)
    seeds = (0,) if args.quick else (0, 1, 2)
    rows = run(objects, materials, seeds)
    doc = {"machine": common.machine_end(info), "materials": materials, "seeds": list(seeds),
           "counts": COUNTS, "views": {str(c): views_of(c) for c in COUNTS},
           "modes": {m: photo_bench.MODES[m] for m in MODES},
           "settings": f"a ring of {N_VIEWS} cameras at 240 x 180, one distant light, 1 % "
                       "noise, fast KL, the default basis without the material",
           "summary": summary(rows), "runs": rows}
    stem = "photo_count_quick" if args.quick else "photo_count"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(doc, path.with_suffix(".png"))
    print(json.dumps(doc["summary"], indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
