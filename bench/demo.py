"""``make demo``: reconstruct a held-out material from optimally chosen samples.

For now the demo exercises the core on a built-in example: a material the basis
never saw (a held-out analytic BRDF) is observed at n condition-optimal cells,
the full table is reconstructed, the errors are printed, and a picture (BRDF
slices at an incident angle of 135 degrees as in the paper's Fig. 4, plus
rendered spheres) and the MERL ``.binary`` are written to ``demo_out/``.
Later work replaces this with the full photo-to-material pipeline.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

from brdf_reconstruct.core import basis, database, merl, metrics, reconstruct, render, sampling

LIGHT = render.REFERENCE_LIGHT


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--material", default=None, help="held-out material name")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="demo_out")
    args = parser.parse_args(argv)

    heldout = {s["name"]: s for s in database.heldout_specs()}
    name = args.material or next(iter(heldout))
    if name not in heldout:
        print(f"error: unknown material {name!r}; choose one of {', '.join(heldout)}",
              file=sys.stderr)
        return 2
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    print("loading the built-in basis (built and cached on first use, ~2 min) ...", flush=True)
    B = basis.load_default(progress=lambda i: print(f"  training table {i}", end="\r",
                                                    flush=True))
    print(f"basis: {B.info['n_components']} components over {B.info['n_cells']} cells "
          f"({time.perf_counter() - t0:.1f} s)")
    truth = database.make_table(heldout[name])
    cells = sampling.optimal_cells(B, merl.cells_from_linear(B.cells), args.samples, args.seed)
    values = truth.reshape(3, -1)[:, merl.linear_index(cells)].T
    rec = reconstruct.reconstruct(B, cells, values)
    truth_img = render.render_sphere(truth, LIGHT)
    rec_img = render.render_sphere(rec.table, LIGHT)
    floor = B.project(truth)
    result = {
        "material": name,
        "samples": int(len(cells)),
        "condition": rec.condition,
        "brdf_log_rmse": metrics.brdf_log_rmse(rec.table, truth),
        "sphere_rel_rmse": metrics.relative_rmse(rec_img, truth_img),
        "projection_floor_sphere_rel_rmse": metrics.relative_rmse(
            render.render_sphere(floor, LIGHT), truth_img),
        "reconstruction": rec.summary(),
    }
    merl.write(out / f"brdf_{name}.binary", rec.table)
    (out / "report.json").write_text(json.dumps(result, indent=1))
    plot(truth, rec.table, truth_img, rec_img, name, out / "demo.png")
    print(json.dumps({k: v for k, v in result.items() if k != "reconstruction"}, indent=1))
    print(f"wrote {out}/demo.png, {out}/brdf_{name}.binary, {out}/report.json "
          f"in {time.perf_counter() - t0:.1f} s")
    return 0


def slice_135(table: np.ndarray, n_points: int = 181):
    """BRDF in the plane of incidence for light at 45 degrees from the normal (the paper's
    'incident angle 135 degrees' plots), view angle from -90 to 90 degrees."""
    ti = np.radians(45.0)
    to = np.radians(np.linspace(-89.5, 89.5, n_points))
    light = np.tile([-np.sin(ti), 0.0, np.cos(ti)], (n_points, 1))
    view = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=1)
    normal = np.tile([0.0, 0.0, 1.0], (n_points, 1))
    return np.degrees(to), merl.evaluate(table, normal, light, view, "trilinear")


def plot(truth, rec, truth_img, rec_img, name, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4), gridspec_kw={"width_ratios": [2, 1, 1]})
    angle, t = slice_135(truth)
    _, r = slice_135(rec)
    for c, colour in enumerate(("r", "g", "b")):
        axes[0].plot(angle, t[:, c], colour + "--", lw=1)
        axes[0].plot(angle, r[:, c], colour + "-", lw=1)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("view angle (degrees), light at 45 degrees")
    axes[0].set_ylabel("BRDF (1/sr)")
    axes[0].set_title(f"{name}: reconstructed (solid) vs ground truth (dashed)", fontsize=9)
    scale = np.percentile(truth_img[truth_img > 0], 99) if np.any(truth_img > 0) else 1.0
    for ax, img, title in ((axes[1], truth_img, "ground truth"),
                           (axes[2], rec_img, "reconstruction")):
        ax.imshow(np.clip(img / scale, 0, 1) ** (1 / 2.2))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
