"""Ours against a Mitsuba 3 Principled fit on the 12 held-out materials (issue 5).

For every held-out material: the 12 analytic ones (``core.brdf.database.heldout_specs``)
and one measured material per class (``testkit.measured.one_per_class``, drawn with
seed 0), the measured ones through a pack without their cross-validation fold
(``measured.pack_without``, given to the batch as ``$BRDF_MEASURED_PACK``):

1. The bunny capture of the demo (``testkit/capture.py``: 6 views, 3 lit photos,
   240 x 180, seed 0), generated once into
   ``basis.default_cache_dir() / "captures" / <key>`` (the key of
   ``bench/demo.py``, ``capture.cache_folder``; ``common.ensure_capture``) and
   reused after.
2. Ours, as a user runs it: ``python -m brdf_reconstruct.brdf_addon.batch`` on a
   copy of the capture's ``job.toml`` with ``preset = "BALANCED"`` under
   ``[settings]``; the table is read back from ``out/brdf_0.binary``. Timed: the
   batch subprocess's wall time, and the stage timings of ``out/report.json``.
3. The peer: ``python -m testkit.mitsuba_peer <capture>`` (``testkit/mitsuba_peer.py``:
   a Principled BSDF fitted by Mitsuba 3 inverse rendering, tabulated on the MERL
   grid; see that module for the set-up), also a subprocess, timed the same way.
4. Both tables scored against ``truth.binary`` with ``metrics.sphere_error``
   (rendered-sphere relative RMSE, the headline) and ``metrics.brdf_log_rmse``.

Steps 2 and 3 run back to back for each material, in alternating order (ours
first on even materials, Mitsuba first on odd ones), so that they share the
machine's load; the 1-minute load average is recorded beside every timing.
Writes ``bench/results/heldout.json`` (per material, medians, the ratios
ours / Mitsuba of the median sphere error and of the median wall time, the
exact command, the convention checks of the peer) and ``heldout.png``.

Run: ``.venv/bin/python bench/heldout_bench.py`` (all 12, about 40 minutes on
2 cores), ``--materials heldout_fabric,heldout_gold_medium``, or ``--quick``
(two materials, a 20-step Mitsuba fit, written to ``heldout_quick.*``).
Needs the dev-only extra: ``.venv/bin/pip install -r requirements-bench.txt``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

import common
import numpy as np

RESULTS = common.RESULTS
QUICK_MATERIALS = ("heldout_gold_medium", "heldout_rough_plastic")
NOTE = ("shared with other jobs: wall times are noisy; load_1min is the 1-minute load "
        "average at each run's start")


def run_ours(folder: pathlib.Path, material: str) -> dict:
    """Run the batch entry on the Balanced job with the default (measured) basis; for
    a measured material, ``$BRDF_MEASURED_PACK`` names a pack without the material's
    cross-validation fold (``measured.pack_without``), so the basis never saw it.
    Returns the table, wall time and the report's stage timings (seconds)."""
    from brdf_reconstruct.core.brdf import merl
    from testkit import capture, measured

    job = capture.preset_job(folder, "BALANCED")
    out = folder / "out"
    if out.exists():
        shutil.rmtree(out)
    env = None
    if common.is_measured(material):
        env = {"BRDF_MEASURED_PACK": str(measured.pack_without(material, folder.parent))}
    done, wall, load = common.run_batch(job, env=env)
    if done.returncode != 0:
        raise RuntimeError(f"batch failed on {job}: {done.stderr.strip()[-500:]}")
    report = json.loads((out / "report.json").read_text())
    if env and report.get("basis", {}).get("source") != env["BRDF_MEASURED_PACK"]:
        raise RuntimeError(f"the batch on {job} did not use the fold's pack: "
                           f"{report.get('basis')}")
    region = report["regions"][0]
    return {"table": merl.read(out / "brdf_0.binary"), "wall_s": wall, "load_1min": load,
            "timings_s": report["timings_s"], "preset": report["settings"]["preset"],
            "basis": report.get("basis"),
            "status": region["status"], "counts": region.get("counts")}


def run_mitsuba(folder: pathlib.Path, iterations: int, spp: int) -> dict:
    """Run ``python -m testkit.mitsuba_peer`` on the capture in a subprocess; table,
    wall time and the peer's own summary (stage seconds, fitted parameters, loss curve,
    camera check)."""
    from brdf_reconstruct.core.brdf import merl

    with tempfile.TemporaryDirectory() as tmp:
        table_path, summary_path = pathlib.Path(tmp) / "fit.binary", pathlib.Path(tmp) / "fit.json"
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "testkit.mitsuba_peer", str(folder),
                               "--iterations", str(iterations), "--spp", str(spp),
                               "--out", str(table_path), "--json", str(summary_path)],
                              capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if done.returncode != 0:
            raise RuntimeError(f"mitsuba_peer failed on {folder}: {done.stderr.strip()[-800:]}")
        summary = json.loads(summary_path.read_text())
        table = merl.read(table_path)
    summary.pop("sphere_error", None)
    summary.pop("brdf_log_rmse", None)
    return {"table": table, "wall_s": wall, "load_1min": load, **summary}


def _median(values) -> float:
    return float(np.median(np.asarray(values, dtype=np.float64)))


def plot(results: dict, path: pathlib.Path) -> None:
    """Bars per material: sphere error, BRDF log RMSE and wall time, ours vs Mitsuba."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    labels = [n.removeprefix("heldout_") for n in names]
    x = np.arange(len(names))
    fig, axes = plt.subplots(3, 1, figsize=(max(8.0, 0.9 * len(names) + 2.0), 10.0),
                             sharex=True)
    panels = (("sphere_error", "sphere relative RMSE"), ("brdf_log_rmse", "BRDF log RMSE"),
              ("wall_s", "wall time (s)"))
    for ax, (key, title) in zip(axes, panels, strict=True):
        ours = [results[n]["ours"][key] for n in names]
        peer = [results[n]["mitsuba"][key] for n in names]
        ax.bar(x - 0.2, ours, 0.4, label=f"ours (Balanced), median {_median(ours):.3g}")
        ax.bar(x + 0.2, peer, 0.4, label=f"Mitsuba 3 Principled fit, median {_median(peer):.3g}")
        ax.set_ylabel(title)
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xticks(x, labels, rotation=30, ha="right")
    axes[0].set_title("Held-out materials, bunny capture (6 views, 3 lit, 240x180)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--materials", help="comma-separated held-out names: analytic "
                        "(heldout_*) or measured (of the pack); default: the 12 analytic "
                        "and one measured material per class (measured.one_per_class)")
    parser.add_argument("--quick", action="store_true",
                        help="two materials and a 20-step fit; writes heldout_quick.*")
    parser.add_argument("--iterations", type=int, default=None,
                        help="Mitsuba Adam steps (default: mitsuba_peer's, --quick 20)")
    parser.add_argument("--spp", type=int, default=None,
                        help="Mitsuba samples per pixel (default: mitsuba_peer's)")
    parser.add_argument("--out", default=None, help="JSON path (default bench/results/...)")
    args = parser.parse_args(argv)

    from brdf_reconstruct.core.brdf import database, merl, metrics
    from testkit import measured, mitsuba_peer

    pack = common.measured_pack_or_error()
    if pack is None:
        return 1
    drawn = measured.one_per_class(pack.names)
    every = [s["name"] for s in database.heldout_specs()] + list(pack.names)
    if args.materials:
        materials = [m.strip() for m in args.materials.split(",") if m.strip()]
    else:
        materials = list(QUICK_MATERIALS) if args.quick else every[:12] + drawn
    unknown = sorted(set(materials) - set(every))
    if unknown:
        print(f"error: unknown material(s) {', '.join(unknown)}; choose from "
              f"{', '.join(every[:12])} or a material of {measured.PACK}", file=sys.stderr)
        return 2
    iterations = args.iterations or (20 if args.quick else mitsuba_peer.DEFAULT_ITERATIONS)
    spp = args.spp or mitsuba_peer.DEFAULT_SPP
    stem = "heldout_quick" if args.quick else "heldout"
    out = pathlib.Path(args.out) if args.out else RESULTS / f"{stem}.json"
    info = common.machine(NOTE)

    command = ".venv/bin/python bench/heldout_bench.py " + " ".join(
        sys.argv[1:] if argv is None else argv)
    print(f"peer convention checks (Mitsuba {_mitsuba_version()}) ...", flush=True)
    checks = {"irradiance": mitsuba_peer.check_irradiance(),
              "tabulation": mitsuba_peer.check_tabulation()}
    print(json.dumps(checks), flush=True)
    results = {}
    t_start = time.perf_counter()
    for i, material in enumerate(materials):
        t0 = time.perf_counter()
        folder, generated_s = common.ensure_capture(material)
        generated = generated_s is not None
        capture_s = time.perf_counter() - t0
        truth = merl.read(folder / "truth.binary")
        runs = {}
        order = ("ours", "mitsuba") if i % 2 == 0 else ("mitsuba", "ours")
        for who in order:
            runs[who] = (run_ours(folder, material) if who == "ours"
                         else run_mitsuba(folder, iterations, spp))
        entry = {"capture": {"folder": str(folder), "generated_now": generated,
                             "seconds": capture_s}, "order": list(order)}
        for who in ("ours", "mitsuba"):
            run = runs[who]
            table = run.pop("table")
            entry[who] = {"sphere_error": metrics.sphere_error(table, truth),
                          "brdf_log_rmse": metrics.brdf_log_rmse(table, truth), **run}
        results[material] = entry
        o, m = entry["ours"], entry["mitsuba"]
        print(f"[{i + 1}/{len(materials)}] {material}: sphere error ours {o['sphere_error']:.4f}"
              f" / Mitsuba {m['sphere_error']:.4f}; log RMSE {o['brdf_log_rmse']:.4f} / "
              f"{m['brdf_log_rmse']:.4f}; wall {o['wall_s']:.1f} s / {m['wall_s']:.1f} s "
              f"(load {o['load_1min']:.1f}); Mitsuba loss {m['loss_curve'][0][1]:.4g} -> "
              f"{m['loss']:.4g}, IoU {min(m['camera_check']['iou_alpha']):.3f}", flush=True)

    medians = {who: {key: _median([results[n][who][key] for n in results])
                     for key in ("sphere_error", "brdf_log_rmse", "wall_s")}
               for who in ("ours", "mitsuba")}
    ratios = {f"{key}_ours_over_mitsuba": medians["ours"][key] / medians["mitsuba"][key]
              for key in ("sphere_error", "brdf_log_rmse", "wall_s")}
    document = {
        "command": command,
        "what": "Ours (batch entry, Balanced preset) against a Mitsuba 3 Principled BSDF fit "
                "by inverse rendering, on the bunny capture of every held-out material; both "
                "tabulated on the MERL grid and scored against the true table. Ratios are "
                "ours / Mitsuba of the medians (< 1: ours lower).",
        "capture": {"views": 6, "lit_photos": 3, "resolution": [240, 180], "seed": 0,
                    "light": "job.toml: [0.35, -0.45, 0.82] normalised, irradiance 1"},
        "ours": {"entry": "python -m brdf_reconstruct.brdf_addon.batch job_balanced.toml",
                 "preset": "BALANCED"},
        "mitsuba": {"entry": f"python -m testkit.mitsuba_peer CAPTURE --iterations "
                             f"{iterations} --spp {spp}",
                    "iterations": iterations, "spp": spp, "lr": mitsuba_peer.DEFAULT_LR,
                    "keys": list(mitsuba_peer.DEFAULT_KEYS),
                    "initial": {k: mitsuba_peer.INITIAL[k] for k in mitsuba_peer.DEFAULT_KEYS},
                    "variant": mitsuba_peer.VARIANT, "version": _mitsuba_version()},
        "checks": checks,
        "machine": common.machine_end(info),
        "total_seconds": time.perf_counter() - t_start,
        "medians": medians, "ratios": ratios, "materials": results,
    }
    common.write_json(out, document, arguments=args)
    plot(results, out.with_suffix(".png"))
    print(json.dumps({"medians": medians, "ratios": ratios}, indent=1))
    print(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


def _mitsuba_version() -> str:
    from importlib.metadata import version

    return version("mitsuba")


if __name__ == "__main__":
    sys.exit(main())
