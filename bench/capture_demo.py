"""The photo-to-material job on a synthetic bunny capture (issue 5, in progress).

1. Generates, or reuses from the cache, a capture (``bench/capture.py``): the
   Stanford bunny degraded as a photogrammetry mesh, a COLMAP model of a camera
   ring, and photos shaded in Cycles by a held-out material's true table.
2. Runs the batch job exactly as a user would:
   ``python -m brdf_reconstruct.brdf_addon.batch job.toml``.
3. Compares the reconstructed table with the truth and writes, to ``--out``:
   ``capture_demo.png`` (BRDF slices with light at 45 degrees, as the paper's
   Fig. 4, and spheres rendered with the truth and the reconstruction),
   ``summary.json``, and the batch outputs (``.binary``, ``report.json``, the
   photo-vs-render picture, ``scene.blend``).

Run: ``.venv/bin/python bench/capture_demo.py [--material NAME]``. Not yet
``make demo``: that switch comes with the rest of issue 5.
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

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--material", default="heldout_gold_medium")
    parser.add_argument("--views", type=int, default=6)
    parser.add_argument("--lit", type=int, default=3, help="cameras that take a lit photo")
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--height", type=int, default=180)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="demo_capture_out")
    args = parser.parse_args(argv)

    from brdf_reconstruct.core import basis, database, merl, metrics, render

    heldout = {s["name"]: s for s in database.heldout_specs()}
    if args.material not in heldout:
        print(f"error: unknown material {args.material!r}; choose one of "
              f"{', '.join(heldout)}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    key = f"{args.material}_{args.views}v{args.lit}l_{args.width}x{args.height}_s{args.seed}"
    cache = basis.default_cache_dir() / "captures" / key
    job = cache / "job.toml"
    truth = database.make_table(heldout[args.material])
    if not job.is_file():
        print(f"generating the capture in {cache} ...", flush=True)
        subprocess.run([sys.executable, str(HERE / "capture.py"), str(cache),
                        "--material", args.material, "--views", str(args.views),
                        "--lit", str(args.lit), "--width", str(args.width),
                        "--height", str(args.height), "--seed", str(args.seed)], check=True)
    else:
        print(f"reusing the capture in {cache}", flush=True)
    out = pathlib.Path(args.out).resolve()
    if (cache / "out").exists():
        shutil.rmtree(cache / "out")
    print("running the batch job ...", flush=True)
    t1 = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                             str(job)], env=dict(os.environ))
    if result.returncode != 0:
        return result.returncode
    batch_s = time.perf_counter() - t1
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(cache / "out", out)
    rec = merl.read(out / "brdf_0.binary")
    light = render.REFERENCE_LIGHT
    truth_img, rec_img = render.render_sphere(truth, light), render.render_sphere(rec, light)
    report = json.loads((out / "report.json").read_text())
    summary = {
        "command": ".venv/bin/python bench/capture_demo.py " + " ".join(argv or sys.argv[1:]),
        "material": args.material, "views": args.views, "lit_photos": args.lit,
        "resolution": [args.width, args.height],
        "sphere_rel_rmse": metrics.relative_rmse(rec_img, truth_img),
        "brdf_log_rmse": metrics.brdf_log_rmse(rec, truth),
        "counts": report["regions"][0]["counts"],
        "batch_seconds": batch_s, "total_seconds": time.perf_counter() - t0,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    import demo

    demo.plot(truth, rec, truth_img, rec_img, f"{args.material} (bunny capture)",
              out / "capture_demo.png")
    print(json.dumps(summary, indent=1))
    print(f"wrote {out}/capture_demo.png and the batch outputs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
