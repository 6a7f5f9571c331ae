"""Reliable-region ablation on synthetic blunted geometry (issue 3, the paper's Fig. 3e
against Sec. 3.1-3.2). Writes ``bench/results/reliable.json`` and ``reliable.png``.

Scene (``core.synthetic``): a height field with sharp ridges and cones, seen from
above; photos are shaded with the TRUE geometry and a held-out material under
four distant lights (1 % noise); the pipeline only sees the BLUNTED, noisy
"photogrammetry" geometry. Variants: all pixels (no constraint), each constraint
alone, all constraints, all constraints + KL selection over random-subset
trials. Error: rendered-sphere relative RMSE and BRDF log RMSE against the
held-out material.

Run: ``make bench`` (or ``.venv/bin/python bench/reliable_bench.py [--quick]``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np

from brdf_reconstruct.core import (
    basis,
    database,
    metrics,
    observations,
    reliable,
    render,
    selection,
    synthetic,
)

RESULTS = pathlib.Path(__file__).resolve().parent / "results"
LIGHT = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
N_SAMPLES = 20
N_TRIALS = 8
VARIANTS = {
    "all_pixels": dict(use_curvature=False, use_monotonicity=False, use_brightest=False),
    "curvature_only": dict(use_curvature=True, use_monotonicity=False, use_brightest=False),
    "monotonicity_only": dict(use_curvature=False, use_monotonicity=True, use_brightest=False),
    "brightest_only": dict(use_curvature=False, use_monotonicity=False, use_brightest=True),
    "all_constraints": dict(),
}


def capture(table, resolution, seed):
    z = synthetic.height_field(resolution)
    truth = synthetic.gbuffer_from_heights(z)
    scan = synthetic.gbuffer_from_heights(synthetic.blunted(z, rng=seed))
    photos = [synthetic.photo(table, truth, light, noise=0.01, rng=seed + i)
              for i, light in enumerate(synthetic.LIGHTS)]
    return truth, scan, photos


def observe_all(scan, photos):
    ones = np.ones(scan.mask.shape)
    region = np.where(scan.mask, 0, -1)
    parts = [observations.observe(p, scan.normal, scan.position, ones, region,
                                  scan.camera_center, light, view_index=i)
             for i, (p, light) in enumerate(zip(photos, synthetic.LIGHTS, strict=True))]
    return observations.concatenate(parts)


def run_material(B, spec, resolution, seed):
    truth_table = database.make_table(spec)
    truth_img = render.render_sphere(truth_table, LIGHT)
    truth, scan, photos = capture(truth_table, resolution, seed)
    t0 = time.perf_counter()
    samples = observe_all(scan, photos)
    t_obs = time.perf_counter() - t0
    errors, counts, times = {}, {}, {"observations_s": t_obs}

    def score(table):
        return {"sphere_rel_rmse": metrics.relative_rmse(render.render_sphere(table, LIGHT),
                                                         truth_img),
                "brdf_log_rmse": metrics.brdf_log_rmse(table, truth_table)}

    for name, options in VARIANTS.items():
        settings = reliable.ReliableSettings(**options)
        t0 = time.perf_counter()
        cand, report = reliable.reliable_candidates(samples, settings)
        times[f"{name}_reliable_s"] = time.perf_counter() - t0
        counts[name] = {"input": report.input, "removed": report.removed, "kept": report.kept}
        (rec, _), = reliable.reconstruct_trials(B, cand, N_SAMPLES, 1, seed, 1.0, report.peaks)
        errors[name] = score(rec.table)
        if name == "all_constraints":
            t0 = time.perf_counter()
            trials = reliable.reconstruct_trials(B, cand, N_SAMPLES, N_TRIALS, seed, 0.5,
                                                 report.peaks)
            views = [selection.View(photo=p, normal=scan.normal,
                                    visibility=np.ones(scan.mask.shape), mask=scan.mask,
                                    position=scan.position, camera_center=scan.camera_center,
                                    light=light)
                     for p, light in zip(photos, synthetic.LIGHTS, strict=True)]
            chosen = selection.select_by_kl([r.table for r, _ in trials], views)
            times["trials_and_kl_s"] = time.perf_counter() - t0
            errors["all_constraints_kl"] = score(trials[chosen.winner][0].table)
            errors["all_constraints_kl"]["kl_per_trial"] = chosen.kl.tolist()
            trial_errors = [score(r.table)["sphere_rel_rmse"] for r, _ in trials]
            errors["all_constraints_kl"]["trial_sphere_errors"] = trial_errors
            errors["all_constraints_kl"]["winner"] = chosen.winner

    # normal-angle error of the pixels the curvature stage keeps against those it drops
    angle = np.degrees(synthetic.normal_angle_error(truth, scan))
    rows, cols = samples.pixel[:, 0], samples.pixel[:, 1]
    keep = np.isfinite(samples.curvature) & (np.abs(samples.curvature)
                                             <= reliable.ReliableSettings().curvature_threshold)
    normal_error = {"kept_median_deg": float(np.median(angle[rows, cols][keep])),
                    "dropped_median_deg": float(np.median(angle[rows, cols][~keep]))
                    if (~keep).any() else None}
    megapixels = len(photos) * resolution**2 / 1e6
    return errors, counts, times, normal_error, megapixels


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    resolution = 128 if args.quick else 256
    specs = database.heldout_specs()[: 4 if args.quick else None]
    B = basis.load_default()
    per_material = {}
    for i, spec in enumerate(specs):
        t0 = time.perf_counter()
        errors, counts, times, normal_error, mp = run_material(B, spec, resolution, seed=i)
        per_material[spec["name"]] = {"errors": errors, "counts": counts, "times": times,
                                      "normal_error": normal_error, "megapixels": mp}
        print(f"{spec['name']}: " + ", ".join(
            f"{k} {v['sphere_rel_rmse']:.3f}" for k, v in errors.items())
            + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    variants = list(VARIANTS) + ["all_constraints_kl"]
    median = {v: float(np.median([m["errors"][v]["sphere_rel_rmse"]
                                  for m in per_material.values()])) for v in variants}
    median_brdf = {v: float(np.median([m["errors"][v]["brdf_log_rmse"]
                                       for m in per_material.values()])) for v in variants}
    obs_mp_s = [m["megapixels"] / (m["times"]["observations_s"]
                                    + m["times"]["all_constraints_reliable_s"])
                for m in per_material.values()]
    report = {
        "command": "make bench  (.venv/bin/python bench/reliable_bench.py)",
        "resolution": resolution, "n_samples": N_SAMPLES, "n_trials": N_TRIALS,
        "ablation": {
            "median_error": median,
            "median_brdf_log_rmse": median_brdf,
            "ratio_all_constraints_kl_to_all_pixels":
                median["all_constraints_kl"] / median["all_pixels"],
        },
        "observation_and_reliable_megapixels_per_second_median": float(np.median(obs_mp_s)),
        "materials": per_material,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "reliable.json").write_text(json.dumps(report, indent=1))
    plot(report, RESULTS / "reliable.png")
    print(json.dumps(report["ablation"], indent=1))
    print("observation + reliable region, MP/s:",
          report["observation_and_reliable_megapixels_per_second_median"])
    return report


def plot(report, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = list(report["ablation"]["median_error"])
    mats = report["materials"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    x = np.arange(len(variants))
    for name, m in mats.items():
        axes[0].plot(x, [m["errors"][v]["sphere_rel_rmse"] for v in variants], ".-", lw=0.6,
                     alpha=0.6, label=name.replace("heldout_", ""))
    axes[0].plot(x, [report["ablation"]["median_error"][v] for v in variants], "k-o", lw=2,
                 label="median")
    axes[0].set_xticks(x, [v.replace("_", "\n") for v in variants], fontsize=7)
    axes[0].set_yscale("log")
    axes[0].set_title("rendered-sphere relative RMSE on blunted geometry", fontsize=9)
    axes[0].legend(fontsize=6, ncol=2)
    kept = [m["normal_error"]["kept_median_deg"] for m in mats.values()]
    dropped = [m["normal_error"]["dropped_median_deg"] or np.nan for m in mats.values()]
    axes[1].bar([0, 1], [np.median(kept), np.nanmedian(dropped)], color=["tab:green", "tab:red"])
    axes[1].set_xticks([0, 1], ["kept by curvature", "dropped by curvature"])
    axes[1].set_ylabel("median normal-angle error (degrees)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
