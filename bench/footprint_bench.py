"""The pixel footprint through the extension: Cycles photos, the batch entry, the
setting ``pixel_footprint`` off and on. Writes ``bench/results/footprint.json`` and
``footprint.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/footprint_bench.py            # 6 materials: about 9 minutes
    .venv/bin/python bench/footprint_bench.py --quick    # 2 materials
    .venv/bin/python bench/footprint_bench.py --materials heldout_fabric,blue-fabric

``bench/optics_bench.py`` measured the footprint on numpy-shaded photos (each
pixel the exact mean of 2 x 2 point shadings). Here the photos are what a user's
camera would give as far as Cycles can: ``testkit/capture.py``'s captures
(6 views on the COLMAP ring, 3 lit photos of 240 x 180, seed 0), rendered by
Cycles with the ground-truth table as the shader (``render_lit_photos``: 16
samples, Cycles' default 1.5-pixel Blackman-Harris pixel filter, so a real pixel
footprint, wider than the pixel's own area). For each object and material:

1. The capture, generated once in a fresh process into the demo's cache
   (``capture.cache_folder``, ``<subject>_<material>_6v3l_240x180_s0``; Spot with
   ``--mesh``); one cached before ``truth.ply`` was written (the demo's bunny
   capture) is left as it is and generated again under
   ``<cache>/captures/footprint_bench/``.
2. Four batch runs, as a user runs them (``python -m brdf_reconstruct.brdf_addon.batch``
   in a fresh process, ``common.run_batch``): the capture's ``job.toml`` with
   ``preset = "BALANCED"`` (seed 0), the scan in {the degraded ``scan.ply``, the
   exact ``truth.ply``: the ground truth in the same frame, its own normals} x
   ``pixel_footprint`` in {false, true}. The order of the four alternates from one
   material to the next (forward, then backward), so that they share the machine's
   load; the 1-minute load average is recorded beside every timing. A measured
   material runs with the pack without its cross-validation fold
   (``measured.pack_without``, as ``$BRDF_MEASURED_PACK``), as heldout_bench does;
   that pack's basis is built into the cache first, untimed (``warm_basis``), so
   the first of the four runs does not pay for it.
3. Scored against ``truth.binary``: ``metrics.sphere_error`` (the headline) and
   ``metrics.brdf_log_rmse``; recorded beside them which table the refinement kept
   (``report.json`` regions[0].refinement.table), the every-pixel refit's relative
   RMSE to the photos, the batch's wall seconds and the report's ``timings_s``.

The frame of ``truth.ply`` is checked once per object (``frame_check``): the
bounding boxes of both PLY files, imported as the job imports them, and the
distance from each vertex of one to the surface of the other.

Summary per (object, scan, footprint): the median over materials of the sphere
error and log RMSE, how often the every-pixel refit was kept, the median wall,
G-buffer, refinement and total seconds; per (object, scan) the geometric-mean ratio
footprint on / off of the sphere error and the median of the per-material time
differences on - off.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import common
import numpy as np

RESULTS = common.RESULTS
CAPTURE = common.DEMO_CAPTURE
OBJECTS = ("bunny", "spot")
SCANS = {"degraded": "scan.ply", "exact": "truth.ply"}
FOOTPRINT = (False, True)
# the analytic materials: a metal, a plastic, a fabric (core.brdf.database.heldout_specs);
# the measured ones: measured.one_per_class's draw (seed 0) of the same three classes
ANALYTIC = ("heldout_gold_medium", "heldout_rough_plastic", "heldout_fabric")
MEASURED_CLASSES = ("metal", "plastic", "fabric")
TIMINGS = ("gbuffers", "pipeline_refinement", "total_before_outputs")
NOTE = ("2 cores shared with other jobs: wall times are noisy; load_1min is the 1-minute "
        "load average at each run's start")


def mesh_of(obj: str):
    """The ground truth's mesh file of ``obj``: None (the capture's default, the
    bunny) or Spot's."""
    from testkit import measured

    return None if obj == "bunny" else measured.DATA / "spot.obj"


def default_materials(quick: bool) -> list[str]:
    """The three analytic materials and the measured draw of the same classes;
    ``quick``: the first of each (a metal, analytic and measured)."""
    from brdf_reconstruct.core.brdf import nbrdf
    from testkit import measured

    drawn = dict(zip(measured.CLASSES, measured.one_per_class(nbrdf.load(measured.PACK).names),
                     strict=True))
    chosen = [drawn[c] for c in MEASURED_CLASSES]
    return [ANALYTIC[0], chosen[0]] if quick else list(ANALYTIC) + chosen


def ensure_capture(obj: str, material: str) -> tuple[pathlib.Path, float | None]:
    """The capture of ``material`` on ``obj`` with ``truth.ply``: the cached one, or
    generated now in a fresh process (``capture.command``). A cached capture
    without ``truth.ply`` is not touched; this one is generated under
    ``<cache>/captures/footprint_bench/`` instead. Returns (folder, seconds the
    generation took or None when cached)."""
    from testkit import capture

    settings = (material, CAPTURE["views"], CAPTURE["lit"], tuple(CAPTURE["resolution"]),
                CAPTURE["seed"])
    folder = capture.cache_folder(*settings, mesh=mesh_of(obj))
    if (folder / "job.toml").is_file() and not (folder / "truth.ply").is_file():
        folder = folder.parent / "footprint_bench" / folder.name
    if (folder / "job.toml").is_file() and (folder / "truth.ply").is_file():
        return folder, None
    t0 = time.perf_counter()
    subprocess.run(capture.command(folder, *settings, mesh=mesh_of(obj)), check=True,
                   stdout=subprocess.DEVNULL)
    return folder, time.perf_counter() - t0


def job_file(folder: pathlib.Path, scan: str, footprint: bool, out: pathlib.Path):
    """A copy of ``folder/job.toml`` with ``mesh`` the scan's file (:data:`SCANS`),
    ``preset = "BALANCED"``, ``pixel_footprint`` and ``out`` (absolute), beside it
    (so its relative paths hold). Returns its path."""
    text = (folder / "job.toml").read_text()
    for old, new in (('mesh = "scan.ply"', f'mesh = "{SCANS[scan]}"'),
                     ("[settings]\n", '[settings]\npreset = "BALANCED"\n'
                      f"pixel_footprint = {'true' if footprint else 'false'}\n"),
                     ('out = "out"', f'out = "{out.as_posix()}"')):
        if old not in text:
            raise RuntimeError(f"{folder / 'job.toml'} has no {old!r}")
        text = text.replace(old, new, 1)
    job = folder / f"job_footprint_{scan}_{'on' if footprint else 'off'}.toml"
    job.write_text(text)
    return job


def warm_basis(material: str, folder: pathlib.Path) -> float | None:
    """For a measured material, build (or load) the basis of the pack without its
    fold (``measured.pack_without``) into the cache now, in a fresh process, so that
    no timed run pays the first build; the seconds it took (None: analytic)."""
    from testkit import measured

    if not common.is_measured(material):
        return None
    pack = measured.pack_without(material, folder.parent)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import sys\nfrom brdf_reconstruct.core.brdf "
                    "import basis\nbasis.load_measured(sys.argv[1])", str(pack)], check=True)
    return time.perf_counter() - t0


def run(obj: str, folder: pathlib.Path, material: str, scan: str, footprint: bool,
        truth) -> dict:
    """One batch run (see the module's step 2), scored against ``truth``."""
    from brdf_reconstruct.core.brdf import merl, metrics
    from testkit import measured

    env = None
    if common.is_measured(material):
        env = {"BRDF_MEASURED_PACK": str(measured.pack_without(material, folder.parent))}
    with tempfile.TemporaryDirectory(prefix="footprint_") as tmp:
        out = pathlib.Path(tmp) / "out"
        job = job_file(folder, scan, footprint, out)
        done, wall, load = common.run_batch(job, env=env)
        if done.returncode != 0:
            raise RuntimeError(f"batch failed on {job}: {done.stderr.strip()[-800:]}")
        report = json.loads((out / "report.json").read_text())
        table = merl.read(out / "brdf_0.binary")
    if env and report.get("basis", {}).get("source") != env["BRDF_MEASURED_PACK"]:
        raise RuntimeError(f"the batch on {job} did not use the fold's pack: "
                           f"{report.get('basis')}")
    if report["settings"]["pixel_footprint"] != footprint:
        raise RuntimeError(f"{job}: the report's pixel_footprint is not {footprint}")
    rendered = [p.get("pixel_footprint") for p in report["capture"]["photos"]]
    region = report["regions"][0]
    refinement = region.get("refinement") or {}
    every = refinement.get("every_pixel") or {}
    return {"object": obj, "material": material, "scan": scan, "footprint": footprint,
            "measured": common.is_measured(material),
            "sphere_error": metrics.sphere_error(table, truth),
            "brdf_log_rmse": metrics.brdf_log_rmse(table, truth),
            "table": refinement.get("table"), "status": region["status"],
            "every_pixel_relative_rmse": every.get("relative_rmse"),
            "every_pixel_kept": every.get("kept"), "every_pixel_by": every.get("by"),
            "footprint_points_per_photo": rendered, "preset": report["settings"]["preset"],
            "wall_s": wall, "load_1min": load,
            **{f"{k}_s": report["timings_s"].get(k) for k in TIMINGS},
            "basis_load_s": report["timings_s"].get("basis_load"),
            "timings_s": report["timings_s"], "basis": report.get("basis", {}).get("source")}


def frame_check(folder: pathlib.Path, mesh) -> dict:
    """The frame of ``folder``'s ``truth.ply`` (:func:`_frame_check_here`), in a fresh
    process (``--frame-check``: it imports meshes into Blender)."""
    done = subprocess.run([sys.executable, str(pathlib.Path(__file__).resolve()),
                           "--frame-check", str(folder), str(mesh or "")],
                          capture_output=True, text=True, check=True)
    line = next(x for x in done.stdout.splitlines() if x.startswith("FRAME "))
    return json.loads(line.removeprefix("FRAME "))


def _frame_check_here(folder: pathlib.Path, mesh) -> dict:
    """``scan.ply`` and ``truth.ply`` imported as the job imports them (Z up): their
    bounding boxes, the distance from each vertex of ``truth.ply`` to the surface of
    the ground truth loaded afresh (``capture.load_ground_truth``, ``mesh``; 0 when
    the exported truth is the one the photos show), and from each ``scan.ply``
    vertex to ``truth.ply``'s surface (the scan's degradation; the unit radius is 1)."""
    import bpy
    from mathutils.bvhtree import BVHTree

    from testkit import capture

    bpy.ops.wm.read_factory_settings(use_empty=True)

    def arrays(obj):
        co = np.zeros(len(obj.data.vertices) * 3)
        obj.data.vertices.foreach_get("co", co)
        return (capture._world(obj, co.reshape(-1, 3)),
                [tuple(p.vertices) for p in obj.data.polygons])

    def ply(name):
        before = set(bpy.data.objects)
        bpy.ops.wm.ply_import(filepath=str(folder / name), forward_axis="Y", up_axis="Z")
        return arrays(next(o for o in bpy.data.objects if o not in before))

    def distances(points, surface):
        tree = BVHTree.FromPolygons([tuple(v) for v in surface[0]], surface[1])
        return np.array([tree.find_nearest(tuple(v))[3] for v in points])

    truth, scan = ply("truth.ply"), ply("scan.ply")
    fresh = arrays(capture.load_ground_truth(mesh) if mesh else capture.default_ground_truth())
    to_fresh, to_truth = distances(truth[0], fresh), distances(scan[0], truth)

    def box(v):
        return [v.min(axis=0).round(5).tolist(), v.max(axis=0).round(5).tolist()]

    return {"truth_box": box(truth[0]), "scan_box": box(scan[0]),
            "truth_vertices": len(truth[0]), "scan_vertices": len(scan[0]),
            "truth_vertices_to_fresh_truth_max": float(to_fresh.max()),
            "scan_vertices_to_truth_median": float(np.median(to_truth)),
            "scan_vertices_to_truth_p95": float(np.percentile(to_truth, 95)),
            "scan_vertices_to_truth_max": float(to_truth.max())}


def _median(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else None


def summary(rows: list) -> dict:
    """Per object and scan: per footprint the medians over materials; the
    geometric-mean ratio on / off of the sphere error and log RMSE, and the median
    per-material time differences on - off."""
    out = {}
    for obj in OBJECTS:
        for scan in SCANS:
            part = [r for r in rows if r["object"] == obj and r["scan"] == scan]
            if not part:
                continue
            entry = {}
            for fp in FOOTPRINT:
                sub = [r for r in part if r["footprint"] == fp]
                entry["on" if fp else "off"] = {
                    "median_sphere_error": _median([r["sphere_error"] for r in sub]),
                    "median_brdf_log_rmse": _median([r["brdf_log_rmse"] for r in sub]),
                    "every_pixel_kept": sum(r["table"] == "every_pixel" for r in sub),
                    "materials": len(sub),
                    **{f"median_{k}": _median([r[k] for r in sub])
                       for k in ("wall_s", *(f"{t}_s" for t in TIMINGS))}}
            pairs = [(next(r for r in part if r["material"] == m and not r["footprint"]),
                      next(r for r in part if r["material"] == m and r["footprint"]))
                     for m in dict.fromkeys(r["material"] for r in part)]
            entry["geometric_mean_ratio_on_over_off"] = {
                k: float(np.exp(np.mean([np.log(on[k] / off[k]) for off, on in pairs])))
                for k in ("sphere_error", "brdf_log_rmse")}
            entry["median_delta_on_minus_off_s"] = {
                k: _median([None if on[k] is None or off[k] is None else on[k] - off[k]
                            for off, on in pairs])
                for k in ("wall_s", *(f"{t}_s" for t in TIMINGS))}
            out[f"{obj}/{scan}"] = entry
    return out


def plot(rows: list, path: pathlib.Path) -> None:
    """One panel per object: per material the sphere error of the four runs (degraded
    and exact scan, footprint off and on), log scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    objects = [o for o in OBJECTS if any(r["object"] == o for r in rows)]
    names = list(dict.fromkeys(r["material"] for r in rows))
    fig, axes = plt.subplots(len(objects), 1, figsize=(max(7.0, 1.3 * len(names) + 2.5) + 3.5,
                                                       3.6 * len(objects)), squeeze=False)
    x = np.arange(len(names))
    bars = [(s, fp) for s in SCANS for fp in FOOTPRINT]
    colours = {("degraded", False): "#b0b0b0", ("degraded", True): "#606060",
               ("exact", False): "#9ecae1", ("exact", True): "#2171b5"}
    for ax, obj in zip(axes[:, 0], objects, strict=True):
        handles = []
        for j, (scan, fp) in enumerate(bars):
            found = [next((r for r in rows if r["object"] == obj and r["material"] == n
                           and r["scan"] == scan and r["footprint"] == fp), None)
                     for n in names]
            values = [np.nan if r is None else r["sphere_error"] for r in found]
            drawn = ax.bar(x + (j - 1.5) * 0.2, values, 0.2, color=colours[scan, fp])
            handles.append(Patch(color=colours[scan, fp],
                                 label=f"{scan} scan, footprint {'on' if fp else 'off'} "
                                       f"(median {np.nanmedian(values):.3f})"))
            for patch, r in zip(drawn, found, strict=True):
                if r is not None and r["table"] == "every_pixel":
                    patch.set_hatch("///")
                    patch.set_edgecolor("white")
        ax.set_yscale("log")
        ax.set_ylabel("sphere error")
        ax.set_xticks(x, [n.removeprefix("heldout_") for n in names], fontsize=8)
        ax.set_title(f"{obj}: Cycles photos (6 views, 3 lit, 240x180), Balanced, seed 0; "
                     "hatched: the every-pixel refit kept", fontsize=9)
        ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.grid(axis="y", alpha=0.3)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--materials", help="comma-separated held-out names: analytic "
                        "(heldout_*) or measured (of the pack); default: "
                        f"{', '.join(ANALYTIC)} and the measured draw of "
                        f"{', '.join(MEASURED_CLASSES)}")
    parser.add_argument("--objects", default=",".join(OBJECTS), help="of bunny, spot")
    parser.add_argument("--quick", action="store_true",
                        help="two materials (an analytic and a measured metal); writes "
                             "footprint_quick.*")
    parser.add_argument("--out", default=None, help="JSON path (default bench/results/...)")
    parser.add_argument("--frame-check", nargs=2, metavar=("FOLDER", "MESH"),
                        help=argparse.SUPPRESS)  # frame_check's own process
    args = parser.parse_args(argv)
    if args.frame_check:
        folder, mesh = args.frame_check
        print("FRAME " + json.dumps(_frame_check_here(pathlib.Path(folder), mesh or None)))
        return 0

    from brdf_reconstruct.core.brdf import database, merl

    pack = common.measured_pack_or_error()
    if pack is None:
        return 1
    objects = common.listed(args.objects, OBJECTS, "--objects")
    if objects is None:
        return 2
    every = [s["name"] for s in database.heldout_specs()] + list(pack.names)
    materials = (common.listed(args.materials, every, "--materials") if args.materials
                 else default_materials(args.quick))
    if materials is None:
        return 2
    if "BRDF_RECONSTRUCT_CACHE" not in os.environ:
        print("note: BRDF_RECONSTRUCT_CACHE is not set; the captures go to the default "
              "cache", file=sys.stderr)
    info = common.machine(NOTE)
    t_start = time.perf_counter()
    rows, captures, frames = [], {}, {}
    k = 0
    for obj in objects:
        for material in materials:
            t0 = time.perf_counter()
            folder, generated = ensure_capture(obj, material)
            captures[f"{obj}/{material}"] = {"folder": str(folder),
                                             "generated_seconds": generated,
                                             "seconds": time.perf_counter() - t0,
                                             "basis_warm_seconds": warm_basis(material,
                                                                              folder)}
            if obj not in frames:
                frames[obj] = {"folder": str(folder), **frame_check(folder, mesh_of(obj))}
                print(f"{obj} frame check: {json.dumps(frames[obj])}", flush=True)
            truth = merl.read(folder / "truth.binary")
            order = [(s, fp) for s in SCANS for fp in FOOTPRINT]
            order = order if k % 2 == 0 else order[::-1]
            k += 1
            line = []
            for scan, fp in order:
                row = run(obj, folder, material, scan, fp, truth)
                rows.append(row)
                line.append(f"{scan}/{'on' if fp else 'off'} {row['sphere_error']:.4f} "
                            f"({row['table']}, {row['wall_s']:.0f} s)")
            print(f"{obj} {material}: " + ", ".join(line), flush=True)
            for job in folder.glob("job_footprint_*.toml"):
                job.unlink()
    doc = {
        "what": "The pixel footprint (setting pixel_footprint) through the extension: "
                "Cycles-rendered photos (16 samples, Cycles' default 1.5 px Blackman-Harris "
                "pixel filter), the batch entry with the Balanced preset at seed 0, on the "
                "degraded scan (scan.ply) and the exact one (truth.ply), footprint off and "
                "on; scored against the true table. Ratios: on / off (< 1: the footprint "
                "helps).",
        "command": (".venv/bin/python bench/footprint_bench.py " + " ".join(
            sys.argv[1:] if argv is None else argv)).strip(),
        "capture": {**CAPTURE, "resolution": list(CAPTURE["resolution"]),
                    "objects": objects, "samples": 16,
                    "light": "job.toml: [0.35, -0.45, 0.82] normalised, irradiance 1"},
        "entry": "python -m brdf_reconstruct.brdf_addon.batch JOB (preset BALANCED, "
                 "pixel_footprint true/false, mesh scan.ply/truth.ply)",
        "materials": materials, "machine": common.machine_end(info),
        "minutes": (time.perf_counter() - t_start) / 60.0,
        "frame_check": frames, "captures": captures,
        "summary": summary(rows), "runs": rows}
    stem = "footprint_quick" if args.quick else "footprint"
    path = common.write_json(pathlib.Path(args.out) if args.out else RESULTS / f"{stem}.json",
                             doc, arguments=args)
    plot(rows, path.with_suffix(".png"))
    print(json.dumps(doc["summary"], indent=1))
    print(f"wrote {path} and {path.with_suffix('.png')} ({doc['minutes']:.1f} min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
