"""What a camera's blur and photos misregistered against the scan cost.
Writes ``bench/results/optics.json`` and ``optics.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/optics_bench.py            # about 40 minutes
    .venv/bin/python bench/optics_bench.py --quick    # 5 materials

The synthetic captures shade each photo on the truth's G-buffers at the very
pixels the scan's G-buffers are read, one shading per pixel: photo and scan are
registered exactly and the photo is point-sampled, as the pipeline models it
(the product renders the scan's G-buffers with a 0.01-pixel filter). A real
photo is neither: a lens, the sensor's pixel and the demosaicing blur it by
about half a pixel to a pixel, and its pose comes from photogrammetry (sub-pixel
reprojection errors at best) on a scan whose surface sits off the true one.
Each photo of ``bench/photo_bench.py``'s captures (the bunny and Spot, the
degraded scan and the exact one; 240 x 180 pixels, 3 photos, 1 % noise) is
changed as ``VARIANTS`` says, then Balanced runs at seed 0 on the 12 analytic and
7 measured held-out materials, each with the default basis without it:

- ``point``: as captured (the photo bench's runs);
- ``footprint``: each pixel the mean radiance over its area, no optics: the
  photo shaded at twice the resolution (480 x 360, the truth's G-buffers rendered
  so) and averaged 2 x 2, then the same 1 % noise, read on the same 240 x 180
  G-buffers of the scan;
- ``footprint, modelled``: the same photos, and the scan's normals at the four
  points of each pixel (its G-buffers rendered at 480 x 360) given as
  ``PhotoInput.footprint_normal``: the refits to every pixel predict each pixel
  as the mean over its area;
- ``blur 0.5``, ``blur 1``: a Gaussian of that many pixels (sigma), the optics;
- ``moved 0.5``: photo p moved by half a pixel along the direction at 120 p
  degrees (``scipy.ndimage.shift``, cubic spline, the nearest value beyond the
  border), a misregistered pose;
- ``moved 0.5 and back``: moved, then moved back the same way: only the
  interpolation's own smoothing, so ``moved 0.5`` against it is the shift's share.

Per row the rendered-sphere error and which table Balanced kept (the judge keeps
the every-pixel refit only where it reproduces the photos); the summary gives per
case and variant the median over materials, the geometric-mean ratio to
``point`` and how often the every-pixel refit was kept.
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

VARIANTS = ("point", "footprint", "footprint, modelled", "blur 0.5", "blur 1", "moved 0.5",
            "moved 0.5 and back")
FINE = 2  # the footprint's photos are shaded at FINE x the resolution, then averaged
SCANS = ("scan", "exact")
SEED = 0


def _moved(image: np.ndarray, p: int, d: float) -> np.ndarray:
    angle = 2.0 * np.pi * p / 3.0
    return ndimage.shift(image, (d * np.sin(angle), d * np.cos(angle), 0.0), order=3,
                         mode="nearest")


def footprint_normals(fine_scan: dict, view: int) -> np.ndarray:
    """(H, W, FINE^2, 3) the scan's normals at the FINE x FINE points of each pixel
    of lit view ``view``, from its G-buffers at FINE x the resolution
    (``fine_scan``, a ``photo_bench.scans`` entry); NaN off the object."""
    n = np.array(fine_scan["scan_normal"][view], dtype=np.float64)
    n[np.asarray(fine_scan["scan_region"][view]) < 0] = np.nan
    h, w = n.shape[0] // FINE, n.shape[1] // FINE
    return n.reshape(h, FINE, w, FINE, 3).swapaxes(1, 2).reshape(h, w, FINE * FINE, 3)


def changed(photos: list, variant: str, fine: list | None = None,
            fine_scan: dict | None = None, seed: int = SEED) -> list:
    """``photos`` (PhotoInput) with each image changed as ``variant`` (of
    ``VARIANTS``) says: photo p moved along the direction at 120 p degrees (rows
    down, columns right), blurred, or (``footprint``) replaced by ``fine``'s
    noiseless photos (the same views at ``FINE`` x the resolution) averaged over
    each pixel's area with 1 % noise, and (``footprint, modelled``) given
    ``fine_scan``'s normals over each pixel; the G-buffers stay."""
    rng = np.random.default_rng(seed)
    out = []
    for p, photo in enumerate(photos):
        image = np.asarray(photo.photo, dtype=np.float64)
        extra = {}
        if variant.startswith("footprint"):
            sharp = np.nan_to_num(np.asarray(fine[p].photo, dtype=np.float64))
            h, w = image.shape[:2]
            mean = sharp.reshape(h, FINE, w, FINE, -1).mean(axis=(1, 3))
            mean *= 1.0 + 0.01 * rng.standard_normal(mean.shape)
            image = np.where(np.isfinite(image), np.maximum(mean, 0.0), image)
            if variant.endswith("modelled"):
                extra["footprint_normal"] = footprint_normals(fine_scan, p)
        elif variant.startswith("blur"):
            sigma = float(variant.split()[1])
            image = ndimage.gaussian_filter(image, (sigma, sigma, 0.0))
        elif variant.startswith("moved"):
            image = _moved(image, p, 0.5)
            if variant.endswith("back"):
                image = _moved(image, p, -0.5)
        out.append(dataclasses.replace(photo, photo=image, **extra))
    return out


def summary(rows: list) -> dict:
    out = {}
    for obj in sorted({r["object"] for r in rows}):
        for scan in SCANS:
            part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
            if not part:
                continue
            base = {r["material"]: r["sphere"] for r in part if r["variant"] == "point"}
            out[f"{obj}/{scan}"] = {
                v: {"median": float(np.median([r["sphere"] for r in part if r["variant"] == v])),
                    "geometric_mean_ratio_to_point": float(np.exp(np.mean(
                        [np.log(r["sphere"] / base[r["material"]])
                         for r in part if r["variant"] == v]))),
                    "every_pixel_kept": sum(r["table"] == "every_pixel"
                                            for r in part if r["variant"] == v)}
                for v in VARIANTS}
    return out


def plot(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [(o, s) for o in sorted({r["object"] for r in rows}) for s in SCANS
             if any(r["object"] == o and r["scan"] == s for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 4), squeeze=False)
    x = np.arange(len(VARIANTS))
    for ax, (obj, scan) in zip(axes[0], cases, strict=True):
        part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
        for name in sorted({r["material"] for r in part}):
            ax.plot(x, [next(r["sphere"] for r in part if r["material"] == name
                             and r["variant"] == v) for v in VARIANTS], "-", lw=0.6, alpha=0.4)
        ax.plot(x, [np.median([r["sphere"] for r in part if r["variant"] == v])
                    for v in VARIANTS], "ko-", lw=2, label="median over materials")
        ax.set_xticks(x, VARIANTS, rotation=30, fontsize=7)
        ax.set_yscale("log")
        ax.set_ylabel("sphere error")
        ax.set_title(f"{obj}, {scan}", fontsize=9)
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials")
    if args is None:
        return objects
    info = common.machine("a camera's blur and misregistered photos, issue 15")
    t0 = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    rows = []
    for obj in objects:
        fine_scans = photo_bench.scans(obj, resolution=(240 * FINE, 180 * FINE))
        for scan, arrays in photo_bench.scans(obj).items():
            for name in names:
                truth = common.heldout_table(name)
                B = common.default_basis_without(name)
                photos = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=SEED)
                fine = capture_arrays.photo_inputs(fine_scans["exact"], truth)  # the truth's
                line = []
                for v in VARIANTS:
                    region = pipeline.run(B, changed(photos, v, fine, fine_scans[scan]),
                                          pipeline.PipelineSettings(seed=SEED),
                                          regions=[0]).regions[0]
                    rows.append({"object": obj, "scan": scan, "material": name, "variant": v,
                                 "measured": common.is_measured(name),
                                 "sphere": metrics.sphere_error(region.table, truth),
                                 "table": region.refinement.get("table")})
                    line.append(f"{v} {rows[-1]['sphere']:.3f} ({rows[-1]['table']})")
                print(f"{obj} {scan} {name}: " + ", ".join(line), flush=True)
    doc = {"machine": common.machine_end(info), "materials": names, "variants": list(VARIANTS),
           "settings": f"Balanced (PipelineSettings(seed={SEED})), 3 photos, 1 % noise, "
                       "each pixel's area averaged (2 x 2 finer photos), Gaussian blur "
                       "(sigma in pixels) or photo p moved at 120 p degrees (cubic spline)",
           "minutes": (time.perf_counter() - t0) / 60.0, "summary": summary(rows), "runs": rows}
    stem = "optics_quick" if args.quick else "optics"
    path = common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(rows, path.with_suffix(".png"))
    for case, entry in doc["summary"].items():
        print(case, {k: round(e["median"], 3) for k, e in entry.items()})
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
