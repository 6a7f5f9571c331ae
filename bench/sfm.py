"""Benchmark: camera recovery by pycolmap SfM from ambient renders of the textured bunny
(the renders, the SfM run and the camera errors are ``testkit/sfm.py``); writes the
report given by ``--out`` (``make bench``: ``bench/results/sfm.json``).

Run: ``.venv/bin/python bench/sfm.py --out bench/results/sfm.json`` (about 4 minutes
on 2 cores at the defaults, 24 views of 640 x 480).
"""

from __future__ import annotations

import argparse
import pathlib
import shlex
import sys

import common

from testkit import sfm as S

NOTE = "wall times on a shared 2-core machine under other jobs' load"


def main(argv=None) -> int:
    """``python bench/sfm.py [--views N] [--width W --height H] [--out JSON]``: render
    the bunny's ambient views, run pycolmap SfM with estimated and with known
    intrinsics (one feature extraction and matching, two mappings), and write
    the camera errors and wall times as JSON."""
    from brdf_reconstruct.core.brdf import basis

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--views", type=int, default=S.DEFAULT_VIEWS)
    parser.add_argument("--width", type=int, default=S.DEFAULT_RESOLUTION[0])
    parser.add_argument("--height", type=int, default=S.DEFAULT_RESOLUTION[1])
    parser.add_argument("--samples", type=int, default=S.RENDER_SAMPLES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--work", default=None,
                        help="folder for images, database and models "
                             "(default: <cache>/sfm, the cache of core.brdf.basis)")
    parser.add_argument("--out", default=None, help="JSON report (default: print only)")
    args = parser.parse_args(argv)
    command = shlex.join([sys.executable, sys.argv[0] if argv is None else __file__,
                          *(sys.argv[1:] if argv is None else argv)])
    work = pathlib.Path(args.work) if args.work else basis.default_cache_dir() / "sfm"
    images = work / "images"
    info = common.machine(NOTE)

    print(f"render: {args.views} views at {args.width}x{args.height}, "
          f"{args.samples} samples ...", flush=True)
    shot = S.render_ambient_views(images, args.views, (args.width, args.height),
                                  seed=args.seed, samples=args.samples)
    names = [p.name for p in shot["images"]]
    print(f"render: {shot['seconds']:.1f} s", flush=True)

    seconds = {"render": shot["seconds"]}
    database = work / "database.db"
    seconds.update(S.extract_and_match(images, database, names, seed=args.seed))
    print(f"extract: {seconds['extract']:.1f} s, match: {seconds['match']:.1f} s", flush=True)
    runs = {}
    for mode, focal in (("estimated", None), ("known", shot["focal_px"])):
        rec, n_models, t_map = S.map_database(database, images, work / f"sparse_{mode}", focal,
                                              seed=args.seed)
        err = S.camera_errors(rec if rec is not None else {}, shot["poses"],
                              true_focal_px=shot["focal_px"], n_images=len(names))
        err["models"] = n_models
        err["seconds_map"] = t_map
        runs[mode] = err
        line = f"map ({mode} intrinsics): {t_map:.1f} s, {err['registered']}/{len(names)} images"
        if "rotation_error_deg" in err:
            line += (f", rotation error median {err['rotation_error_deg']['median']:.3f} deg,"
                     f" centre error median {100 * err['centre_error_rel']['median']:.2f} %,"
                     f" reprojection {err['mean_reprojection_error_px']:.2f} px,"
                     f" {err['num_points3D']} points, f {err['focal_px'][0]:.1f} px"
                     f" (true {shot['focal_px']:.1f})")
        print(line, flush=True)
    seconds["map_estimated"] = runs["estimated"]["seconds_map"]
    seconds["map_known"] = runs["known"]["seconds_map"]

    common.machine_end(info)
    report = {
        "command": command,
        "views": args.views, "resolution": [args.width, args.height],
        "focal_px": shot["focal_px"], "seed": args.seed,
        "render": {"engine": "CYCLES (CPU)", "samples": args.samples, "denoise": False,
                   "max_bounces": 1, "texture_scale": S.TEXTURE_SCALE, "ambient": 1.0,
                   "png": "8-bit RGB, Standard view transform"},
        "sift": {"device": "cpu", "camera_mode": "SINGLE", "matching": "exhaustive"},
        "camera_ring": {"distance": 3.5, "elevations_deg": [-10.0, 20.0, 50.0]},
        "pycolmap": info.get("pycolmap"),
        "seconds": seconds,
        "machine": info,
        "sfm": runs,
    }
    if args.out:
        out = common.write_json(args.out, report, arguments=args, indent=2)
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
