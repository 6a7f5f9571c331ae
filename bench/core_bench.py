"""Core benchmark: reconstruction error against the number of samples, optimal against
random, on held-out analytic materials ("optimal": the default Bayes-risk cells;
"condition": the paper's condition-optimal cells, on which Nielsen's reconstruction
variants are measured too); projection floor; basis build, load and
reconstruction costs. Writes ``bench/results/core.json`` and ``core.png``.

Run: ``make bench`` (or ``.venv/bin/python bench/core_bench.py [--quick]``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import common
import numpy as np

from brdf_reconstruct.core.brdf import basis, database, merl, metrics, render
from brdf_reconstruct.core.method import reconstruct, sampling

RESULTS = common.RESULTS
SAMPLE_COUNTS = (1, 2, 5, 10, 20, 40)
LIGHT = render.REFERENCE_LIGHT
SPHERE_RES = 96
# Alternatives to the defaults of reconstruct() (p = k, eta by evidence), measured on
# the paper's condition-optimal cells: Nielsen's p = min(n, k) ("n" stands for the
# sample count), p chosen by evidence, and the reference code's fixed eta = 40 with
# p = min(n, k).
VARIANTS_ON_CONDITION = (
    ("condition, p = min(n, k)", {"n_components": "n"}),
    ("condition, p by evidence", {"select_components": True}),
    ("condition, eta = 40 (Nielsen)", {"eta": 40.0, "n_components": "n"}),
)
METHODS = ("optimal", "condition", "random") + tuple(m for m, _ in VARIANTS_ON_CONDITION)


def sphere_error(table, truth_image):
    return metrics.relative_rmse(render.render_sphere(table, LIGHT, SPHERE_RES), truth_image)


def measure_build(n_components: int) -> dict:
    """Build the default basis from scratch in a child process: wall time, peak RSS,
    file size, then load time."""
    with tempfile.TemporaryDirectory() as cache:
        code = (
            "import time, resource, json;"
            "from brdf_reconstruct.core.brdf import basis;"
            "t=time.perf_counter();"
            f"b=basis.load_default(cache_dir={cache!r}, n_components={n_components});"
            "print(json.dumps({'seconds': time.perf_counter()-t,"
            " 'peak_rss_bytes': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss*1024,"
            " 'info': b.info}))"
        )
        out = subprocess.run(
            [sys.executable, "-c", code], check=True, capture_output=True, text=True
        )
        built = json.loads(out.stdout.strip().splitlines()[-1])
        files = list(pathlib.Path(cache).glob("basis-*.npz"))
        size = files[0].stat().st_size
        t = time.perf_counter()
        basis.load(files[0])
        load_s = time.perf_counter() - t
    return {
        "build_seconds": built["seconds"],
        "build_peak_rss_bytes": built["peak_rss_bytes"],
        "cache_file_bytes": size,
        "load_seconds": load_s,
        "info": built["info"],
    }


def table_generation_seconds(specs) -> dict:
    times = []
    for spec in specs:
        t = time.perf_counter()
        database.make_table(spec)
        times.append(time.perf_counter() - t)
    slowest = int(np.argmax(times))
    return {"median": float(np.median(times)), "max": float(times[slowest]),
            "slowest": specs[slowest]["name"], "count": len(times)}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer seeds, no build timing")
    args = parser.parse_args(argv)
    seeds = (0, 1) if args.quick else (0, 1, 2, 3)
    RESULTS.mkdir(parents=True, exist_ok=True)

    report: dict = {"machine": common.machine(),
                    "command": "make bench  (.venv/bin/python bench/core_bench.py)"}
    if not args.quick:
        print("basis build from scratch (child process) ...", flush=True)
        report["basis"] = measure_build(basis.N_COMPONENTS)
        report["table_generation_seconds"] = table_generation_seconds(
            database.training_specs() + database.heldout_specs())
        print(json.dumps(report["basis"], indent=1), flush=True)

    B = basis.load_default()
    candidates = merl.cells_from_linear(B.cells)
    heldout = database.heldout_specs()
    truths = {s["name"]: database.make_table(s) for s in heldout}
    truth_images = {k: render.render_sphere(t, LIGHT, SPHERE_RES) for k, t in truths.items()}

    floor = {}
    for name, t in truths.items():
        proj = B.project(t)
        floor[name] = {"brdf_log_rmse": metrics.brdf_log_rmse(proj, t),
                       "sphere_rel_rmse": sphere_error(proj, truth_images[name])}
    report["projection_floor"] = floor

    rows = []
    recon_times = []
    sample_times = {"risk": {}, "condition": {}}
    for n in SAMPLE_COUNTS:
        for seed in seeds:
            designs = {}
            for criterion in sampling.CRITERIA:
                t = time.perf_counter()
                designs[criterion] = sampling.optimal_cells(B, candidates, n, seed,
                                                            criterion=criterion)
                sample_times[criterion].setdefault(n, []).append(time.perf_counter() - t)
            rng = np.random.default_rng(1000 + seed)
            rand = candidates[rng.choice(len(candidates), n, replace=False)]
            runs = [("optimal", designs["risk"], {}), ("condition", designs["condition"], {}),
                    ("random", rand, {})]
            runs += [(method, designs["condition"],
                      {k: n if v == "n" else v for k, v in options.items()})
                     for method, options in VARIANTS_ON_CONDITION]
            for method, cells, options in runs:
                rows_b = B.rows_of(merl.linear_index(cells))
                cond = sampling.acquisition_condition(B.Q, rows_b)
                risk = sampling.design_risk(B, rows_b)
                for name, truth in truths.items():
                    values = truth.reshape(3, -1)[:, merl.linear_index(cells)].T
                    t = time.perf_counter()
                    rec = reconstruct.reconstruct(B, cells, values, **options)
                    if method == "optimal":
                        recon_times.append(time.perf_counter() - t)
                    rows.append({
                        "n": n, "seed": seed, "method": method, "material": name,
                        "condition": cond, "risk": risk,
                        "brdf_log_rmse": metrics.brdf_log_rmse(rec.table, truth),
                        "sphere_rel_rmse": sphere_error(rec.table, truth_images[name]),
                        "eta": rec.eta.tolist(), "n_components": rec.n_components.tolist(),
                    })
        print(f"n={n} done", flush=True)
    report["runs"] = rows

    summary = {}
    for n in SAMPLE_COUNTS:
        entry = {}
        for method in METHODS:
            sel = [r for r in rows if r["n"] == n and r["method"] == method]
            entry[method] = {
                "median_condition": float(np.median([r["condition"] for r in sel])),
                "median_risk": float(np.median([r["risk"] for r in sel])),
                "median_brdf_log_rmse": float(np.median([r["brdf_log_rmse"] for r in sel])),
                "median_sphere_rel_rmse": float(np.median([r["sphere_rel_rmse"] for r in sel])),
            }
        summary[str(n)] = entry
    report["summary"] = summary
    report["projection_floor_median"] = {
        "brdf_log_rmse": float(np.median([f["brdf_log_rmse"] for f in floor.values()])),
        "sphere_rel_rmse": float(np.median([f["sphere_rel_rmse"] for f in floor.values()])),
    }
    report["timing"] = {
        "reconstruct_seconds_median": float(np.median(recon_times)),
        "optimal_cells_seconds_median": {c: {str(k): float(np.median(v))
                                             for k, v in per_n.items()}
                                         for c, per_n in sample_times.items()},
    }
    report["heldout_materials"] = [s["name"] for s in heldout]

    common.machine_end(report["machine"])
    common.write_json(RESULTS / "core.json", report, arguments=args)
    plot(report, RESULTS / "core.png")
    print(json.dumps({"summary": summary, "floor": report["projection_floor_median"],
                      "timing": report["timing"]}, indent=1))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"peak RSS of this run: {peak:.2f} GB")
    return report


def plot(report: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns = [int(n) for n in report["summary"]]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for ax, key, floor_key, title in (
        (axes[0], "median_sphere_rel_rmse", "sphere_rel_rmse", "rendered sphere, relative RMSE"),
        (axes[1], "median_brdf_log_rmse", "brdf_log_rmse", "BRDF cosine-weighted log RMSE"),
    ):
        for method, style in zip(METHODS, ("o-", "P-", "s--", "d-.", "^:", "v:"), strict=True):
            ax.plot(ns, [report["summary"][str(n)][method][key] for n in ns], style, label=method)
        ax.axhline(report["projection_floor_median"][floor_key], color="k", lw=0.8,
                   label="projection floor")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("samples n")
        ax.set_title(f"median over held-out materials: {title}", fontsize=9)
        ax.legend(fontsize=8)
    for method, style in (("optimal", "o-"), ("condition", "P-"), ("random", "s--")):
        axes[2].plot(ns, [report["summary"][str(n)][method]["median_risk"] for n in ns],
                     style, label=method)
    axes[2].set_xscale("log")
    axes[2].set_yscale("log")
    axes[2].set_xlabel("samples n")
    axes[2].set_title("median Bayes risk of the cells (sampling.design_risk)", fontsize=9)
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
