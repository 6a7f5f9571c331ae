"""``make demo``: the photo-to-material job on a synthetic bunny capture.

1. Loads (or, on a fresh machine, builds and caches, about 2 min) the built-in
   PCA basis of measured-style BRDFs.
2. Generates, or reuses from the cache, a capture (``testkit/capture.py``): the
   Stanford bunny degraded as a photogrammetry mesh (decimated, blunted,
   noisy), a COLMAP model of a camera ring, and linear EXR photos under one
   distant light shaded in Cycles by a held-out material's true table (the
   basis never saw it).
3. Runs the batch job exactly as a user would:
   ``python -m brdf_reconstruct.brdf_addon.batch job.toml`` (Balanced preset).
4. Writes ``demo_out/``: the batch outputs (``brdf_0.binary``, ``report.json``,
   ``scene.blend``, the photo-vs-render and reliable-region pictures, the
   BRDF slice), ``fig4.png`` (the paper's Fig. 4 for this run: BRDF slices,
   reconstructed against ground truth, at an incident angle of 135 degrees,
   and spheres rendered with the truth and the reconstruction),
   ``summary.json`` and ``logs/``.

Run: ``make demo`` (or ``.venv/bin/python bench/demo.py [--material NAME]``).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time

import numpy as np

MARKER = ".brdf_demo_output"
"""A file the demo leaves in its output folder: only a folder holding it (or
nothing) is replaced by the next run."""


def _unsafe_out(out: pathlib.Path) -> str:
    """Why ``out`` must not be replaced by the demo, or "" when it may: it does not
    exist, is empty, or holds the demo's marker (or, from before the marker, the
    demo's own ``summary.json``). Never the checkout, a parent of it, or a file."""
    here = pathlib.Path(__file__).resolve().parent.parent
    if out == here or out in here.parents:
        return f"--out {out} is the checkout or holds it; choose a new folder"
    if not out.exists():
        return ""
    if not out.is_dir():
        return f"--out {out} is a file; choose a folder"
    if not any(out.iterdir()) or (out / MARKER).is_file():
        return ""
    try:
        made_by_demo = json.loads((out / "summary.json").read_text()).get(
            "command", "").startswith("make demo")
    except (OSError, ValueError, AttributeError):
        made_by_demo = False
    if made_by_demo and set(p.name for p in out.iterdir()) <= _DEMO_FILES:
        return ""
    return (f"--out {out} holds files the demo did not make; choose another folder "
            "or empty it (nothing was changed)")


_DEMO_FILES = {"brdf_0.binary", "brdf_0_photo_vs_render.png", "brdf_0_reliable_region.png",
               "brdf_0_slice.png", "fig4.png", "logs", "report.json", "scene.blend",
               "summary.json", "job.toml"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--material", default="heldout_gold_medium",
                        help="held-out material of the capture")
    parser.add_argument("--views", type=int, default=6, help="cameras in the COLMAP ring")
    parser.add_argument("--lit", type=int, default=3, help="cameras that take a lit photo")
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--height", type=int, default=180)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="BALANCED", choices=("FAST", "BALANCED",
                                                                 "ACCURATE", "PAPER"))
    parser.add_argument("--out", default="demo_out")
    args = parser.parse_args(argv)

    from brdf_reconstruct.core.brdf import basis, database, merl, metrics, render

    heldout = {s["name"]: s for s in database.heldout_specs()}
    if args.material not in heldout:
        print(f"error: unknown material {args.material!r}; choose one of "
              f"{', '.join(heldout)}", file=sys.stderr)
        return 2
    from testkit import capture

    subject = capture.default_subject()
    if subject != "bunny":  # the capture falls back to Suzanne, which needs more pixels
        print(f"note: {capture.DATA / 'stanford-bunny.obj'} not found (set BRDF_SHARED_DATA "
              "to its folder); the capture uses Blender's Suzanne instead, 8 views, 4 lit",
              flush=True)
        args.views, args.lit = max(args.views, 8), max(args.lit, 4)
    out = pathlib.Path(args.out).resolve()
    refusal = _unsafe_out(out)
    if refusal:
        print(f"error: {refusal}", file=sys.stderr)
        return 2
    if out.exists():
        shutil.rmtree(out)  # a previous demo's output, marked as ours
    (out / "logs").mkdir(parents=True)
    (out / MARKER).write_text("made by bench/demo.py (make demo); replaced by the next run\n")
    t0 = time.perf_counter()

    print("[1/4] the BRDF basis, measured (built once and cached, about 30 s on a fresh "
          "machine)",
          flush=True)
    B = basis.load_measured(progress=lambda _f, message: print(f"      {message}", end="\r",
                                                              flush=True))
    print(f"      {B.n_components} components over {len(B.cells)} cells "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)

    settings = (args.material, args.views, args.lit, (args.width, args.height), args.seed)
    cache = capture.cache_folder(*settings)
    t1 = time.perf_counter()
    if (cache / "job.toml").is_file():
        print(f"[2/4] reusing the capture in {cache}", flush=True)
    else:
        print(f"[2/4] generating the capture in {cache} (Cycles)", flush=True)
        code = _run(capture.command(cache, *settings), out / "logs" / "capture.log",
                    ("capture:",))
        if code != 0:
            print(f"error: the capture failed; see {out / 'logs' / 'capture.log'}",
                  file=sys.stderr)
            return 1
    capture_s = time.perf_counter() - t1

    print(f"[3/4] the batch job, as a user runs it ({args.preset.title()} preset)", flush=True)
    user_job = capture.preset_job(cache, args.preset, out=out)
    print(f"      .venv/bin/python -m brdf_reconstruct.brdf_addon.batch {user_job}", flush=True)
    t2 = time.perf_counter()
    code = _run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch", str(user_job)],
                out / "logs" / "batch.log", ("[", "done:", "error:"))
    batch_s = time.perf_counter() - t2
    if code != 0:
        return code

    print("[4/4] pictures and errors against the ground truth", flush=True)
    truth = database.make_table(heldout[args.material])
    rec = merl.read(out / "brdf_0.binary")
    light = render.REFERENCE_LIGHT
    truth_img, rec_img = render.render_sphere(truth, light), render.render_sphere(rec, light)
    report = json.loads((out / "report.json").read_text())
    region = report["regions"][0]
    summary = {
        "command": "make demo  (" + " ".join(
            [".venv/bin/python bench/demo.py", *(argv or sys.argv[1:])]) + ")",
        "object": subject, "material": args.material, "preset": args.preset,
        "views": args.views,
        "lit_photos": args.lit, "resolution": [args.width, args.height],
        "sphere_error": metrics.sphere_error(rec, truth),
        "brdf_log_rmse": metrics.brdf_log_rmse(rec, truth),
        "bake_error": region.get("material", {}).get("bake_error"),
        "counts": region["counts"],
        "seconds": {"capture": capture_s, "batch": batch_s,
                    "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    plot(truth, rec, truth_img, rec_img, f"{args.material} ({subject} capture)",
         out / "fig4.png")
    print(f"      rendered-sphere error {summary['sphere_error']:.3f} (3 evaluation lights), "
          f"BRDF log RMSE {summary['brdf_log_rmse']:.3f}")
    print(f"done in {summary['seconds']['total']:.0f} s: {out}/fig4.png, "
          "brdf_0.binary, report.json, scene.blend, brdf_0_photo_vs_render.png, "
          "brdf_0_reliable_region.png", flush=True)
    return 0


def _run(command, log: pathlib.Path, show: tuple) -> int:
    """Run ``command``; lines starting with one of ``show`` go to the terminal (the
    progress display), every line to ``log``. Returns the exit status."""
    with open(log, "w") as sink:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   text=True, env=dict(os.environ), bufsize=1)
        for line in process.stdout:
            sink.write(line)
            if line.startswith(show):
                print("      " + line.rstrip(), flush=True)
        return process.wait()


def slice_135(table: np.ndarray, n_points: int = 181):
    """BRDF in the plane of incidence for light at 45 degrees from the normal (the paper's
    'incident angle 135 degrees' plots), view angle from -90 to 90 degrees.
    Returns (angles (P,) degrees, values (P, 3) 1/sr)."""
    from brdf_reconstruct.core.brdf import merl

    ti = np.radians(45.0)
    to = np.radians(np.linspace(-89.5, 89.5, n_points))
    light = np.tile([-np.sin(ti), 0.0, np.cos(ti)], (n_points, 1))
    view = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=1)
    normal = np.tile([0.0, 0.0, 1.0], (n_points, 1))
    return np.degrees(to), merl.evaluate(table, normal, light, view, "trilinear")


def plot(truth, rec, truth_img, rec_img, name, path):
    """The paper's Fig. 4 layout: slices (solid reconstructed, dashed truth) and spheres."""
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
    axes[0].set_xlabel("view angle (degrees); incident light at 135 degrees")
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
