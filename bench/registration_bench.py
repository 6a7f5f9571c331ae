"""What photos misregistered against the scan by a fraction of a pixel cost.
Writes ``bench/results/registration.json`` and ``registration.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/registration_bench.py            # about 25 minutes
    .venv/bin/python bench/registration_bench.py --quick    # 5 materials

The synthetic captures shade each photo on the truth's G-buffers at the very
pixels the scan's G-buffers are read: photo and scan are registered exactly. A
real capture is not: the lit photos' poses come from photogrammetry (sub-pixel
reprojection errors at best) and the scan's surface sits off the true one. Here
each photo of ``bench/photo_bench.py``'s captures (the bunny and Spot, the
degraded scan and the exact one; 240 x 180 pixels, 3 photos, 1 % noise) is moved
by ``d`` pixels (``SHIFTS``), photo p along the direction at 120 p degrees
(``scipy.ndimage.shift``, cubic spline, the nearest value beyond the border), and
Balanced runs at seed 0 on the 12 analytic and 7 measured held-out materials,
each with the default basis without it. The photos are point-sampled (one
shading per pixel, no pixel footprint), so a shift of a sharp highlight is
interpolated between samples: a pessimistic stand-in for a real photo's optics.

Per row the rendered-sphere error and which table Balanced kept; the summary
gives per case and ``d`` the median over materials and the geometric-mean ratio
to ``d`` = 0.
"""
from __future__ import annotations

import dataclasses
import time

import capture_arrays
import common
import numpy as np
import photo_bench
from scipy import ndimage

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import pipeline
from testkit import measured

SHIFTS = (0.0, 0.25, 0.5, 1.0)  # pixels
SCANS = ("scan", "exact")
SEED = 0


def shifted(photos: list, d: float) -> list:
    """``photos`` (PhotoInput) with each photo p's image moved by ``d`` pixels along
    the direction at 120 p degrees (rows down, columns right); the G-buffers stay."""
    out = []
    for p, photo in enumerate(photos):
        angle = 2.0 * np.pi * p / 3.0
        move = (d * np.sin(angle), d * np.cos(angle), 0.0)
        image = np.asarray(photo.photo, dtype=np.float64)
        out.append(dataclasses.replace(photo, photo=image if d == 0.0 else ndimage.shift(
            image, move, order=3, mode="nearest")))
    return out


def summary(rows: list) -> dict:
    out = {}
    for obj in sorted({r["object"] for r in rows}):
        for scan in SCANS:
            part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
            if not part:
                continue
            base = {r["material"]: r["sphere"] for r in part if r["shift"] == 0.0}
            out[f"{obj}/{scan}"] = {
                f"d={d:g}": {
                    "median": float(np.median([r["sphere"] for r in part if r["shift"] == d])),
                    "geometric_mean_ratio_to_d0": float(np.exp(np.mean(
                        [np.log(r["sphere"] / base[r["material"]])
                         for r in part if r["shift"] == d]))),
                    "every_pixel_kept": sum(r["table"] == "every_pixel"
                                            for r in part if r["shift"] == d)}
                for d in SHIFTS}
    return out


def plot(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [(o, s) for o in sorted({r["object"] for r in rows}) for s in SCANS
             if any(r["object"] == o and r["scan"] == s for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 4), squeeze=False)
    x = np.arange(len(SHIFTS))
    for ax, (obj, scan) in zip(axes[0], cases, strict=True):
        part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
        for name in sorted({r["material"] for r in part}):
            ax.plot(x, [next(r["sphere"] for r in part if r["material"] == name
                             and r["shift"] == d) for d in SHIFTS], "-", lw=0.6, alpha=0.4)
        ax.plot(x, [np.median([r["sphere"] for r in part if r["shift"] == d]) for d in SHIFTS],
                "ko-", lw=2, label="median of 19")
        ax.set_xticks(x, [f"{d:g}" for d in SHIFTS])
        ax.set_yscale("log")
        ax.set_xlabel("photos moved against the scan (pixels)")
        ax.set_ylabel("sphere error")
        ax.set_title(f"{obj}, {scan}", fontsize=9)
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials")
    if args is None:
        return objects
    info = common.machine("photos misregistered against the scan, issue 15")
    t0 = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj in objects:
        degraded = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                           else measured.DATA / "spot.obj")
        for scan, arrays in (("scan", degraded), ("exact", photo_bench.exact_scan(degraded))):
            for name in names:
                truth = common.heldout_table(name)
                B = common.default_basis_without(name)
                photos = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=SEED)
                line = []
                for d in SHIFTS:
                    region = pipeline.run(B, shifted(photos, d),
                                          pipeline.PipelineSettings(seed=SEED),
                                          regions=[0]).regions[0]
                    rows.append({"object": obj, "scan": scan, "material": name, "shift": d,
                                 "measured": common.is_measured(name),
                                 "sphere": metrics.sphere_error(region.table, truth),
                                 "table": region.refinement.get("table")})
                    line.append(f"{d:g} px {rows[-1]['sphere']:.3f}")
                print(f"{obj} {scan} {name}: " + ", ".join(line), flush=True)
    doc = {"machine": common.machine_end(info), "materials": names, "shifts": list(SHIFTS),
           "settings": f"Balanced (PipelineSettings(seed={SEED})), 3 photos, 1 % noise, "
                       "photo p moved by d pixels at 120 p degrees (cubic spline)",
           "minutes": (time.perf_counter() - t0) / 60.0, "summary": summary(rows), "runs": rows}
    stem = "registration_quick" if args.quick else "registration"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(rows, path.with_suffix(".png"))
    for case, entry in doc["summary"].items():
        print(case, {k: round(e["median"], 3) for k, e in entry.items()})
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
