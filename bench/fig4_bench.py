"""The paper's Fig. 4 with the paper's materials: aluminium, fruitwood-241, pink-fabric2
and green-latex reconstructed from the blunted bunny capture, and from a second
object (Spot) degraded the same way.

    .venv/bin/python bench/fig4_bench.py [--seed S] [--objects bunny,spot]

For each material (a measured MERL material of the pack, ``testkit.measured.PACK``):

- the **measured** basis of the cross-validation fold that holds the material out
  (``testkit.measured.folds``: built from the 64 others, refused by
  ``measured.held_out`` if it had seen it), and the **analytic** basis beside it;
- the capture's G-buffers (``capture_arrays.gbuffers``: Cycles, the degraded
  "photogrammetry" scan of ``testkit/capture.py``; cached) of the bunny or of
  ``spot.obj``, and three photos of the material's table shaded on the true
  geometry with 1 % noise
  (``capture_arrays.photo_inputs``), as in ``bench/tradeoff.py``;
- ``core.method.pipeline.run`` with the Balanced preset's settings (the pipeline's
  defaults: 20 samples x 16 trials, the fast KL).

Scores: ``metrics.sphere_error`` (three evaluation lights) and
``metrics.brdf_log_rmse`` of the chosen table. Writes
``bench/results/fig4_measured.json`` and ``docs/fig4_measured.png`` (the bunny;
``fig4_measured_spot.png`` for Spot): per material, the BRDF in the plane of
incidence for light at 135 degrees (the paper's plot: truth dashed,
reconstructions solid) and the spheres under the reference light. About 5
minutes an object on the 2-core machine (plus the G-buffers once).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import capture_arrays
import common
import numpy as np
from demo import slice_135

from brdf_reconstruct.core.brdf import basis, metrics, nbrdf, render
from brdf_reconstruct.core.method import pipeline
from testkit import measured

MATERIALS = ("aluminium", "fruitwood-241", "pink-fabric2", "green-latex")  # the paper's
DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
FIGURES = {"bunny": DOCS / "fig4_measured.png", "spot": DOCS / "fig4_measured_spot.png"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0, help="noise and trials (default 0)")
    parser.add_argument("--objects", default="bunny,spot", help="of bunny, spot")
    args = parser.parse_args(argv)
    objects = common.listed(args.objects, FIGURES, "--objects")
    if objects is None:
        return 2
    pack = common.measured_pack_or_error()
    if pack is None:
        return 1
    info = common.machine("the paper's Fig. 4 materials on degraded captures")
    analytic = basis.load_default()
    bases = {name: common.default_basis_without(name) for name in MATERIALS}
    doc = {"objects": {}}
    for obj in objects:
        arrays = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                         else measured.DATA / "spot.obj")
        rows, figure = _object(arrays, pack, bases, analytic, args.seed)
        doc["objects"][obj] = {
            "materials": rows,
            "median_sphere_error": {b: float(np.median([r[b]["sphere_error"] for r in rows]))
                                    for b in ("measured", "analytic")},
            "normal_error_deg": np.asarray(arrays["normal_error_deg"]).tolist()}
        plot(figure, FIGURES[obj])
        print(obj, json.dumps(doc["objects"][obj]["median_sphere_error"]), flush=True)
    doc["machine"] = common.machine_end(info)
    doc["settings"] = "pipeline defaults (the Balanced preset), 3 photos, 1 % noise"
    path = common.write_json(common.RESULTS / "fig4_measured.json", doc,
                             arguments=vars(args))
    print(f"-> {path}")
    return 0


def _object(arrays, pack, bases, analytic, seed):
    settings = pipeline.PipelineSettings(seed=seed)
    rows, figure = [], []
    for name in MATERIALS:
        t0 = time.perf_counter()
        truth = nbrdf.tabulate(pack, pack.index(name))
        inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
        row = {"material": name, "class": measured.material_class(name)}
        tables = {}
        for label, B in (("measured", bases[name]), ("analytic", analytic)):
            region = pipeline.run(B, inputs, settings).regions[0]
            table = np.asarray(region.candidates[region.winner], dtype=np.float64)
            if not np.all(np.isfinite(table[np.isfinite(truth)])):
                raise AssertionError(f"{name}, {label}: the table holds NaN or Inf")
            tables[label] = table
            row[label] = {"sphere_error": metrics.sphere_error(table, truth),
                          "brdf_log_rmse": metrics.brdf_log_rmse(table, truth),
                          "reliable_samples": int(region.counts["reliable"])}
        row["seconds"] = time.perf_counter() - t0
        rows.append(row)
        figure.append((name, truth, tables))
        print(f"  {name}: sphere error measured {row['measured']['sphere_error']:.3f}, "
              f"analytic {row['analytic']['sphere_error']:.3f} ({row['seconds']:.0f} s)",
              flush=True)
    return rows, figure


def plot(figure, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(figure), 4, figsize=(15, 3.3 * len(figure)),
                             gridspec_kw={"width_ratios": [2.2, 1, 1, 1]})
    light = render.REFERENCE_LIGHT
    for row, (name, truth, tables) in zip(axes, figure, strict=True):
        angle, t = slice_135(truth)
        for c, colour in enumerate(("r", "g", "b")):
            row[0].plot(angle, t[:, c], colour + "--", lw=1)
            row[0].plot(angle, slice_135(tables["measured"])[1][:, c], colour + "-", lw=1)
            row[0].plot(angle, slice_135(tables["analytic"])[1][:, c], colour + ":", lw=1)
        row[0].set_yscale("log")
        row[0].set_ylabel("BRDF (1/sr)")
        row[0].set_title(f"{name}: truth dashed, measured basis solid, analytic dotted",
                         fontsize=9)
        images = [render.render_sphere(x, light) for x in
                  (truth, tables["measured"], tables["analytic"])]
        scale = np.percentile(images[0][images[0] > 0], 99) if np.any(images[0] > 0) else 1.0
        for ax, img, title in zip(row[1:], images, ("ground truth", "measured basis",
                                                    "analytic basis"), strict=True):
            ax.imshow(np.clip(img / scale, 0, 1) ** (1 / 2.2))
            ax.set_title(title, fontsize=9)
            ax.axis("off")
    axes[-1][0].set_xlabel("view angle (degrees); incident light at 135 degrees")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
