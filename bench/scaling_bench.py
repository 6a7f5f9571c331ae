"""Time and peak memory of the core pipeline against photos and pixels (issue 5).
Writes ``bench/results/scaling.json`` and ``scaling.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/scaling_bench.py            # about 30 minutes on 2 shared cores
    .venv/bin/python bench/scaling_bench.py --quick    # small frames, writes scaling_quick.*
    .venv/bin/python bench/scaling_bench.py --max-gib 8   # lower memory budget per point

Two sweeps of the whole core run (``core.method.pipeline.run`` with default
``PipelineSettings``, then the bake ``core.bake.fitting.fit`` on the chosen table, as
the extension does), on the bunny of ``bench/capture_arrays.py`` with the
held-out gold (``MATERIAL``), photos shaded by numpy on the truth's Cycles
G-buffers with 1 % noise, the pipeline given the scan's G-buffers:

- photos: 1, 2, 4, 8, 16, 32 photos of 1152 x 864 (0.995 MP, 4:3), from 32
  distinct cameras (``capture.camera_ring(32)``: three rings at -10, 20 and 50
  degrees elevation) all lit by the capture light; n photos are every (32/n)-th
  camera, so each set contains the smaller ones;
- pixels: 3 photos (cameras 0, 2, 4 of the 6-camera ring, the capture's) of
  576 x 432, 816 x 612, 1152 x 864, 1632 x 1224 and 2304 x 1728 (0.25 to 4 MP).
  Here the G-buffers are rendered by Cycles afresh (no cache), and the seconds
  per photo of the scan's G-buffer render are recorded (what a user's run costs
  before the pipeline starts).

Every point runs in its own child process (``--child``, not for direct use), so
its peak memory is that process's own high-water mark (``VmHWM``; ``ru_maxrss``
would be the same, except that on Linux it inherits the parent's peak across
the (v)fork + exec, see :func:`_peak_bytes`); it also reports its resident
memory after loading the basis and after building the inputs, and the bytes the
``PhotoInput`` arrays hold (float64 photos and G-buffers, int32 regions, as
``capture_arrays.photo_inputs`` makes them). The parent watches each child's
resident memory and kills it above the budget (``--max-gib``), and before each
point predicts its peak from the smaller points (linear in megapixels); a point
predicted above the budget, or above the memory the machine has free, is not run
and the JSON says so. Fits: log-log slopes of time and memory against photos
and against megapixels.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import os
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import common
import numpy as np

HERE = common.HERE
RESULTS = common.RESULTS
COMMAND = ".venv/bin/python bench/scaling_bench.py"
MATERIAL = "heldout_gold_medium"
NOISE = 0.01
PHOTO_COUNTS = (1, 2, 4, 8, 16, 32)
PHOTO_RESOLUTION = (1152, 864)
RING = 32  # cameras of the photo-count sweep
RESOLUTIONS = ((576, 432), (816, 612), (1152, 864), (1632, 1224), (2304, 1728))
RESOLUTION_VIEWS = (0, 2, 4)  # of the 6-camera ring, as the capture
STAGES = ("observations", "reliable", "sampling", "reconstruction", "selection", "bake")
GIB = common.GIB
NOTE = ("shared machine: other jobs (Cycles renders, tests, other benchmarks) ran on the same "
        "2 cores during the run; every point ran once, so the seconds carry that load (noise "
        "of tens of percent), memory does not")


# ------------------------------------------------------------------------- child side
def _rss_bytes() -> int:
    """Resident memory of this process now, bytes."""
    return common.proc_status_bytes("VmRSS")


def _cpu_s() -> float:
    """User + system CPU seconds of this process so far (all its threads)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _peak_bytes() -> int:
    """Peak resident memory of this process so far, bytes: VmHWM, the high-water mark of
    its own address space. Not ``ru_maxrss``: on Linux that one carries the parent's
    peak over a (v)fork + exec (the parent's Cycles renders reach several GiB), so it
    reads the same for every point; it is reported as ``ru_maxrss`` for reference."""
    return common.proc_status_bytes("VmHWM")


def _ru_maxrss_bytes() -> int:
    """getrusage(RUSAGE_SELF).ru_maxrss in bytes (KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def load_inputs(files: list[str]) -> list:
    """``pipeline.PhotoInput``s from the per-view ``.npz`` files :func:`prepare` wrote:
    photo (H, W, 3) float64 radiance; scan normal, position (H, W, 3) and visibility
    (H, W) float32 from Cycles, widened to float64 as ``capture_arrays.photo_inputs``
    does; region (H, W) int32; camera_center, light (3,) float64."""
    from brdf_reconstruct.core.method import pipeline

    inputs = []
    for path in files:
        with np.load(path) as d:
            inputs.append(pipeline.PhotoInput(
                photo=d["photo"], normal=d["normal"].astype(np.float64),
                position=d["position"].astype(np.float64),
                visibility=d["visibility"].astype(np.float64), region=d["region"],
                camera_center=d["camera_center"], light=d["light"],
                name=pathlib.Path(path).stem))
    return inputs


def child(spec: dict) -> dict:
    """One point: load the basis and the inputs, run the pipeline and the bake, and
    return seconds per stage and memory in bytes."""
    from brdf_reconstruct.core.bake import fitting
    from brdf_reconstruct.core.brdf import basis
    from brdf_reconstruct.core.method import pipeline

    t0 = time.perf_counter()
    B = basis.load_default()
    out = {"load_basis_s": time.perf_counter() - t0, "rss_after_basis": _rss_bytes()}
    t0 = time.perf_counter()
    inputs = load_inputs(spec["files"])
    out["load_inputs_s"] = time.perf_counter() - t0
    out["input_bytes"] = int(sum(a.nbytes for p in inputs for a in (
        p.photo, p.normal, p.position, p.visibility, p.region)))
    out["pixels"] = int(sum(p.region.size for p in inputs))
    out["foreground_pixels"] = int(sum(np.count_nonzero(p.region >= 0) for p in inputs))
    gc.collect()
    out["rss_before_run"] = _rss_bytes()
    out["peak_before_run"] = _peak_bytes()
    t0, c0 = time.perf_counter(), _cpu_s()
    result = pipeline.run(B, inputs, pipeline.PipelineSettings())
    out["pipeline_s"] = time.perf_counter() - t0
    out["pipeline_cpu_s"] = _cpu_s() - c0
    region = next(r for r in result.regions if r.status == "ok")
    t0, c0 = time.perf_counter(), _cpu_s()
    fitting.fit(region.table)
    bake = time.perf_counter() - t0
    out["bake_cpu_s"] = _cpu_s() - c0
    out["total_cpu_s"] = out["pipeline_cpu_s"] + out["bake_cpu_s"]
    out["stages_s"] = {k: float(result.timings.get(k, 0.0)) for k in STAGES if k != "bake"}
    out["stages_s"]["bake"] = bake
    out["total_s"] = out["pipeline_s"] + bake
    out["samples_observed"] = int(sum(c["samples"] for c in result.photo_counts))
    out["samples_reliable"] = int(region.counts.get("reliable", 0))
    out["peak_rss"] = _peak_bytes()
    out["ru_maxrss"] = _ru_maxrss_bytes()
    return out


# ------------------------------------------------------------------------ parent side
def prepare(workdir: pathlib.Path, tag: str, table: np.ndarray, resolution, n_views: int,
            lit_views, cache: bool) -> tuple[list[str], dict]:
    """Render (or load) the G-buffers, shade the photos, write one ``.npz`` per lit view
    into ``workdir``; returns the file names and the render facts (Cycles seconds per
    photo of the scan's G-buffer, wall seconds of the whole render, 0 if cached)."""
    import capture_arrays as CA

    arrays = CA.gbuffers(resolution=resolution, n_views=n_views, lit_views=lit_views,
                         cache=cache)
    files = []
    for j in range(len(lit_views)):
        [p] = CA.photo_inputs(arrays, table, noise=NOISE, seed=j, views=[j])
        path = workdir / f"{tag}_view{j:02d}.npz"
        np.savez(path, photo=p.photo, normal=arrays["scan_normal"][j],
                 position=arrays["scan_position"][j],
                 visibility=arrays["scan_visibility"][j], region=arrays["scan_region"][j],
                 camera_center=arrays["camera_center"][j], light=arrays["light"])
        files.append(str(path))
    facts = {"render_wall_s": float(arrays["render_s"]),
             "rendered_now": bool(arrays["render_s"] > 0),
             "scan_gbuffer_s_per_photo": float(arrays["scan_gbuffer_s"])
             if "scan_gbuffer_s" in arrays else None,
             "foreground_fraction": float(np.mean(arrays["scan_region"] >= 0)),
             "parent_peak_rss_gib_so_far": _peak_bytes() / GIB}
    del arrays
    gc.collect()
    return files, facts


def run_child(spec: dict, budget: int, poll_s: float = 0.2) -> dict:
    """Run one point in a child process, killing it (by its pid) if its resident memory
    passes ``budget`` bytes; returns its JSON, or a dict with ``error``."""
    cmd = [sys.executable, str(pathlib.Path(__file__).resolve()), "--child", json.dumps(spec)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    watched_peak, killed = 0, False
    while proc.poll() is None:
        rss = common.proc_status_bytes("VmRSS", proc.pid)
        watched_peak = max(watched_peak, rss)
        if rss > budget:
            proc.kill()
            killed = True
            break
        time.sleep(poll_s)
    stdout, stderr = proc.communicate()
    wall = time.perf_counter() - t0
    if killed:
        return {"error": f"killed: resident memory passed the budget of {budget / GIB:.1f} GiB",
                "watched_peak_rss": watched_peak, "wall_s": wall}
    if proc.returncode != 0:
        return {"error": f"child exited with {proc.returncode}: {stderr.strip()[-2000:]}",
                "watched_peak_rss": watched_peak, "wall_s": wall}
    out = json.loads(stdout.strip().splitlines()[-1])
    out["wall_s"] = wall
    return out


def predict_peak(done: list[dict], megapixels: float) -> float | None:
    """Peak bytes at ``megapixels``, linear in megapixels through the last two points
    (None with fewer than two)."""
    pts = [(d["megapixels"], d["peak_rss"]) for d in done if "peak_rss" in d]
    if len(pts) < 2:
        return None
    (x0, y0), (x1, y1) = pts[-2], pts[-1]
    slope = (y1 - y0) / (x1 - x0) if x1 != x0 else 0.0
    return y1 + max(slope, 0.0) * (megapixels - x1)


def sweep(name: str, points: list[dict], budget: int) -> list[dict]:
    """Run the points in ascending size, each in a child; stop (and say why) at the
    first point predicted not to fit."""
    done = []
    for pt in points:
        predicted = predict_peak(done, pt["megapixels"])
        free = common.meminfo_bytes("MemAvailable")
        limit = min(budget, free - 2 * GIB)
        row = dict(pt, predicted_peak_gib=None if predicted is None else predicted / GIB)
        if predicted is not None and predicted > limit:
            row["skipped"] = (f"predicted peak {predicted / GIB:.1f} GiB exceeds the limit "
                              f"{limit / GIB:.1f} GiB (budget {budget / GIB:.1f}, machine free "
                              f"{free / GIB:.1f} GiB minus 2 GiB)")
            print(f"  {name} {pt['label']}: SKIPPED, {row['skipped']}", flush=True)
            done.append(row)
            break
        print(f"  {name} {pt['label']}: running ({pt['megapixels']:.2f} MP"
              + (f", predicted peak {predicted / GIB:.1f} GiB" if predicted else "") + ")",
              flush=True)
        res = run_child({"files": pt["files"]}, limit)
        row.update(res)
        row.pop("files", None)
        done.append(row)
        if "error" in res:
            print(f"  {name} {pt['label']}: FAILED, {res['error'][:300]}", flush=True)
            break
        print(f"  {name} {pt['label']}: total {res['total_s']:.1f} s ("
              + ", ".join(f"{k} {v:.1f}" for k, v in res["stages_s"].items())
              + f"), peak {res['peak_rss'] / GIB:.2f} GiB, inputs "
              f"{res['input_bytes'] / GIB:.2f} GiB, wall {res['wall_s']:.0f} s", flush=True)
    for row in done:
        row.pop("files", None)
    return done


def slope(x, y) -> float | None:
    """Least-squares slope of log y against log x (None with < 2 positive points)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    if np.count_nonzero(ok) < 2:
        return None
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def fits(rows: list[dict], xkey: str, budget_gib: float, machine_gib: float) -> dict:
    """Log-log slopes of time and memory against ``xkey`` over all points run and over
    the largest three; lines (fixed + per megapixel of photos) and the megapixels of
    photos whose predicted peak fits the budget and the machine; the dominant stage at
    the largest point."""
    rows = [r for r in rows if "total_s" in r]
    if len(rows) < 2:
        return {"note": "fewer than two points ran"}
    x = [r[xkey] for r in rows]
    series = {"total_s": [r["total_s"] for r in rows],
              "total_cpu_s": [r["total_cpu_s"] for r in rows],
              "peak_rss": [r["peak_rss"] for r in rows],
              "pipeline_extra_rss": [r["peak_rss"] - r["rss_before_run"] for r in rows],
              "input_bytes": [r["input_bytes"] for r in rows]}
    series.update({f"{k}_s": [r["stages_s"][k] for r in rows] for k in STAGES})
    out = {"slope_all": {k: slope(x, v) for k, v in series.items()},
           "slope_largest_3": {k: slope(x[-3:], v[-3:]) for k, v in series.items()}}
    # fixed cost + cost per megapixel of photos (least squares, all points run)
    mp = np.array([r["megapixels"] for r in rows])
    out["linear_in_megapixels"] = {}
    for k, scale, unit in (("total_s", 1.0, "s"), ("total_cpu_s", 1.0, "s"),
                           ("peak_rss", GIB, "GiB"), ("input_bytes", GIB, "GiB")):
        b, a = np.polyfit(mp, np.asarray(series[k]) / scale, 1)
        out["linear_in_megapixels"][k] = {f"fixed_{unit}": float(a),
                                          f"per_megapixel_{unit}": float(b)}
    mem = out["linear_in_megapixels"]["peak_rss"]
    out["megapixels_of_photos_that_fit"] = {
        f"budget_{budget_gib:g}_gib": (budget_gib - mem["fixed_GiB"]) / mem["per_megapixel_GiB"],
        f"whole_machine_{machine_gib:g}_gib": (machine_gib - mem["fixed_GiB"])
        / mem["per_megapixel_GiB"]}
    top = rows[-1]
    stage = max(STAGES, key=lambda k: top["stages_s"][k])
    out["largest_point"] = {xkey: top[xkey], "megapixels": top["megapixels"],
                            "total_s": top["total_s"], "peak_rss_gib": top["peak_rss"] / GIB,
                            "input_gib": top["input_bytes"] / GIB,
                            "dominant_stage": stage,
                            "dominant_stage_share": top["stages_s"][stage] / top["total_s"],
                            "stage_shares": {k: top["stages_s"][k] / top["total_s"]
                                             for k in STAGES}}
    return out


def describe(f: dict, what: str) -> str:
    """One sentence on how the cost grows, from :func:`fits`."""
    if "slope_all" not in f:
        return f"{what}: {f.get('note')}"
    s, s3, top = f["slope_all"], f["slope_largest_3"], f["largest_point"]
    lin = f["linear_in_megapixels"]
    key = next(k for k in f["megapixels_of_photos_that_fit"] if k.startswith("whole_machine"))
    machine, fit_machine = float(key.split("_")[2]), f["megapixels_of_photos_that_fit"][key]
    return (f"Against {what}: wall time grows as x^{s['total_s']:.2f} over all points "
            f"(x^{s3['total_s']:.2f} over the largest three; CPU time x^{s['total_cpu_s']:.2f}"
            f", x^{s3['total_cpu_s']:.2f}); as a line, {lin['total_s']['fixed_s']:.0f} s fixed "
            f"+ {lin['total_s']['per_megapixel_s']:.1f} s per megapixel of photos (CPU: "
            f"{lin['total_cpu_s']['fixed_s']:.0f} s + {lin['total_cpu_s']['per_megapixel_s']:.1f}"
            f" s/MP). Peak memory grows as "
            f"x^{s['peak_rss']:.2f} (its part above the basis and inputs as "
            f"x^{s['pipeline_extra_rss']:.2f}; the inputs as x^{s['input_bytes']:.2f}), "
            f"{lin['peak_rss']['fixed_GiB']:.2f} GiB + {lin['peak_rss']['per_megapixel_GiB']:.3f}"
            f" GiB per megapixel, so the whole {machine:g} GiB machine would hold about "
            f"{fit_machine:.0f} MP of photos in one run (e.g. {fit_machine / 24:.0f} photos of "
            f"24 MP). "
            f"At the largest point ({top['megapixels']:.1f} MP of photos) the run took "
            f"{top['total_s']:.0f} s and {top['peak_rss_gib']:.2f} GiB peak; "
            f"{top['dominant_stage']} dominates ({100 * top['dominant_stage_share']:.0f} % of "
            f"the time; per-stage slopes: "
            + ", ".join(f"{k} {s[k + '_s']:.2f}" for k in STAGES if s[k + '_s'] is not None)
            + ").")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="1, 2, 4 photos of 576x432 and 2 resolutions; scaling_quick.*")
    parser.add_argument("--max-gib", type=float, default=12.0,
                        help="memory budget per point, GiB (the machine has 24, shared)")
    parser.add_argument("--refit", action="store_true",
                        help="no runs: recompute the fits, sentences and plot of the "
                        "existing scaling.json (scaling_quick.json with --quick)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.refit:
        stem = "scaling_quick" if args.quick else "scaling"
        write(summarise(json.loads((RESULTS / f"{stem}.json").read_text())), stem, args,
              invocation_key="refit_invocation")
        return 0
    if args.child:
        print(json.dumps(child(json.loads(args.child))), flush=True)
        return 0
    from brdf_reconstruct.core.brdf import database

    t_start = time.perf_counter()
    info = common.machine(NOTE)
    budget = int(args.max_gib * GIB)
    counts = PHOTO_COUNTS[:3] if args.quick else PHOTO_COUNTS
    ring = 4 if args.quick else RING
    photo_res = RESOLUTIONS[0] if args.quick else PHOTO_RESOLUTION
    resolutions = RESOLUTIONS[:2] if args.quick else RESOLUTIONS
    spec = common.heldout_spec(MATERIAL)
    table = database.make_table(spec)
    cache_root = pathlib.Path(os.environ.get("BRDF_RECONSTRUCT_CACHE", HERE.parent / ".cache"))
    cache_root.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cache_root, prefix="scaling_") as tmp:
        work = pathlib.Path(tmp)
        print(f"scaling: rendering/loading G-buffers, {ring} cameras at "
              f"{photo_res[0]}x{photo_res[1]}", flush=True)
        ring_files, ring_facts = prepare(work, "ring", table, photo_res, ring, tuple(range(ring)),
                                         cache=True)
        mp = photo_res[0] * photo_res[1] / 1e6
        photo_points = []
        for n in counts:
            pick = np.round(np.arange(n) * ring / n).astype(int)
            photo_points.append({"label": f"{n} photos", "photos": n, "views": pick.tolist(),
                                 "resolution": list(photo_res), "megapixels_per_photo": mp,
                                 "megapixels": n * mp,
                                 "files": [ring_files[i] for i in pick]})
        res_points = []
        for w, h in resolutions:
            print(f"scaling: rendering G-buffers {w}x{h} x {len(RESOLUTION_VIEWS)} (no cache, "
                  "timed)", flush=True)
            files, facts = prepare(work, f"res{w}x{h}", table, (w, h), 6, RESOLUTION_VIEWS,
                                   cache=False)
            res_points.append(dict({"label": f"{w}x{h}", "photos": len(files),
                                    "resolution": [w, h], "megapixels_per_photo": w * h / 1e6,
                                    "megapixels": len(files) * w * h / 1e6, "files": files},
                                   cycles=facts))
            print(f"  Cycles scan G-buffer {facts['scan_gbuffer_s_per_photo']:.2f} s per photo"
                  f" (whole render incl. truth and scene {facts['render_wall_s']:.1f} s)",
                  flush=True)
        print("scaling: photo-count sweep", flush=True)
        photos_rows = sweep("photos", photo_points, budget)
        print("scaling: pixel sweep", flush=True)
        pixel_rows = sweep("pixels", res_points, budget)
    common.machine_end(info)
    report = {
        "command": f"BRDF_RECONSTRUCT_CACHE=/work/main/.cache {COMMAND}"
                   + (" --quick" if args.quick else "")
                   + (f" --max-gib {args.max_gib:g}" if args.max_gib != 12.0 else ""),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": info,
        "memory_budget_gib": args.max_gib,
        "material": spec,
        "photo_noise_relative": NOISE,
        "settings": "pipeline.PipelineSettings() defaults (20 cells, 16 trials, KL over "
                    "64 bins); bake = fitting.fit(chosen table) with its error report, as "
                    "brdf_addon.runner does",
        "notes": [
            f"Photo-count sweep: {ring} distinct cameras rendered by Cycles at "
            f"{photo_res[0]}x{photo_res[1]} (capture.camera_ring({ring}): rings at -10, 20 "
            "and 50 degrees elevation), all lit by capture_arrays.LIGHT; n photos = every "
            f"({ring}/n)-th camera. No view is repeated.",
            "Pixel sweep: cameras 0, 2, 4 of the 6-camera ring, G-buffers rendered afresh "
            "(cache=False); cycles.scan_gbuffer_s_per_photo is the Cycles time of the scan's "
            "G-buffer per photo (what a user's run pays before the pipeline), "
            "render_wall_s the whole render (scene, truth and scan, all views).",
            "Memory: peak_rss is the child's own peak resident memory, /proc VmHWM (basis + "
            "inputs + pipeline + bake). Not its getrusage ru_maxrss (kept as ru_maxrss): "
            "on Linux that inherits the parent's peak across subprocess's vfork + exec, and "
            "the parent's Cycles renders reach several GiB (cycles.parent_peak_rss_gib_so_far)"
            ", so ru_maxrss reads about the parent's peak at every point (4.0 GiB here, "
            "8.4 GiB in a run that rendered the 32 cameras too); "
            "rss_after_basis after loading the PCA basis; input_bytes the PhotoInput arrays "
            "(float64 photo, normal, position, visibility; int32 region); pipeline_extra = "
            "peak_rss - rss_before_run.",
            "Stages: observations, reliable, sampling, reconstruction, selection from "
            "PipelineResult.timings (summed over regions; the bunny is one region), bake = "
            "fitting.fit. Seconds are wall time of one run on a loaded machine.",
        ],
        "photos": photos_rows,
        "pixels": pixel_rows,
        "cycles_ring_render": ring_facts,
        "benchmark_wall_s": time.perf_counter() - t_start,
    }
    write(summarise(report), "scaling_quick" if args.quick else "scaling", args)
    return 0


def summarise(report: dict) -> dict:
    """Add the fits, the growth sentences, the largest points and the stopped points to
    a report holding the rows (``photos``, ``pixels``); returns it."""
    budget, machine_gib = report["memory_budget_gib"], report["machine"]["memory_total_gib"]
    photo_fit = fits(report["photos"], "photos", budget, machine_gib)
    pixel_fit = fits(report["pixels"], "megapixels_per_photo", budget, machine_gib)
    stopped = [r for r in report["photos"] + report["pixels"] if "skipped" in r or "error" in r]
    report.update({
        "growth": {"photos": describe(photo_fit, "the number of photos ({:.2g} MP each)".format(
                       report["photos"][0]["megapixels_per_photo"])),
                   "pixels": describe(pixel_fit, "megapixels per photo (3 photos)")},
        "largest_point_that_ran": {
            "photos": photo_fit.get("largest_point"), "pixels": pixel_fit.get("largest_point")},
        "stopped_points": [{k: r.get(k) for k in ("label", "skipped", "error")}
                           for r in stopped],
        "fits": {"photos": photo_fit, "pixels": pixel_fit}})
    return report


def write(report: dict, stem: str, args, invocation_key: str = "invocation") -> None:
    """``bench/results/<stem>.json`` (through ``common.write_json``, the command and
    ``args`` recorded under ``invocation_key``) and ``.png``; prints the growth
    sentences."""
    common.write_json(RESULTS / f"{stem}.json", report, arguments=args,
                      invocation_key=invocation_key)
    plot(report, RESULTS / f"{stem}.png")
    print(report["growth"]["photos"])
    print(report["growth"]["pixels"])
    print(f"wrote {RESULTS / stem}.json/.png (benchmark {report['benchmark_wall_s']:.0f} s)",
          flush=True)


def plot(report: dict, path: pathlib.Path) -> None:
    """2 x 2 log-log panels: seconds (total and per stage) and memory (peak, above the
    inputs, inputs) against photos and against megapixels per photo."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(13, 9.5))
    for col, (key, xkey, xlabel) in enumerate((
            ("photos", "photos", "photos ({}x{} each)".format(*report["photos"][0]["resolution"])),
            ("pixels", "megapixels_per_photo", "megapixels per photo (3 photos)"))):
        rows = [r for r in report[key] if "total_s" in r]
        if not rows:
            continue
        x = np.array([r[xkey] for r in rows])
        ax = axes[0, col]
        ax.plot(x, [r["total_s"] for r in rows], "k-o", lw=2, label="total (wall)")
        ax.plot(x, [r["total_cpu_s"] for r in rows], "k:", lw=1, label="total CPU (2 threads)")
        for stage in STAGES:
            ax.plot(x, [max(r["stages_s"][stage], 1e-3) for r in rows], ".--", label=stage)
        if key == "pixels":
            ax.plot(x, [r["cycles"]["scan_gbuffer_s_per_photo"] for r in rows], "m:s",
                    label="Cycles scan G-buffer, per photo")
        s = report["fits"][key]["slope_all"]
        ax.set_title(f"time vs {key}: total slope {s['total_s']:.2f} (log-log)", fontsize=10)
        ax.set_ylabel("seconds (wall, shared machine)")
        ax = axes[1, col]
        ax.plot(x, [r["peak_rss"] / GIB for r in rows], "k-o", lw=2, label="peak RSS (process)")
        ax.plot(x, [(r["peak_rss"] - r["rss_before_run"]) / GIB for r in rows], "r--s",
                label="peak above basis + inputs")
        ax.plot(x, [r["input_bytes"] / GIB for r in rows], "b-.^", label="PhotoInput arrays")
        ax.plot(x, [r["rss_after_basis"] / GIB for r in rows], "g:", label="after basis load")
        ax.set_title(f"memory vs {key}: peak slope {s['peak_rss']:.2f}", fontsize=10)
        ax.set_ylabel("GiB")
        for ax in axes[:, col]:
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xticks(x, [f"{v:g}" for v in np.round(x, 2)])
            ax.minorticks_off()
            ax.set_xlabel(xlabel)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7)
    fig.suptitle(f"Core pipeline scaling, bunny, {report['material']['name']} "
                 f"({report['date'][:10]}, {report['machine']['cpu_count']} shared cores)",
                 fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
