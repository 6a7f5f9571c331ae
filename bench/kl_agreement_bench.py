"""Do the fast (numpy) KL and the Cycles KL rank a region's trials alike, on the bunny
capture? (issue 15: "the fast and Cycles KL rankings correlate at 0.8 or more")

    .venv/bin/python bench/kl_agreement_bench.py [--quick] [--seeds S]
        [--materials a,b] [--cycles-samples 4,16]

The capture is the demo's (``testkit/capture.py``, cached by ``common.ensure_capture``):
the degraded bunny scan, a COLMAP model of 6 cameras, 3 lit EXR photos rendered by
Cycles with the held-out material's true table. Its ``job.toml`` is applied to an
empty Blender scene by the batch entry's own code (``brdf_addon.job.load`` /
``apply``) and the photos are gathered as the runner gathers them
(``gathering.gather_capture``: read, light, Cycles G-buffers of the scan).

Per material and seed, ``core.method.pipeline.run`` with the Balanced preset's
settings (``props.pipeline_settings`` of the scene on preset BALANCED: 20 samples x 16
trials, fast KL) and the default basis that never saw the material
(``common.default_basis_without``). Its ``region.kl`` (the fast KL of each trial) is
set against the Cycles KL of the same 16 candidate tables (``cycles_select.
score_candidate``, called as ``runner.Run._cycles_step`` calls it: the table as a
tabulated-BRDF material for the photo's light, ``brdf_addon.table_shader``, rendered
by Cycles from each photo's camera under that light, KL against the photo over the
region's pixels, mean over photos; before 2026-12-03 the path rendered each table's
baked lobes instead) at the Accurate preset's
``kl_samples`` (``--cycles-samples``: any list of counts).

Per material: Spearman and Kendall correlation of the two rankings (``scipy.stats``),
whether the winners agree, the fast winner's rank under Cycles (1 = Cycles' best),
and the sphere error (``metrics.sphere_error`` against the true table) of the fast
winner, the Cycles winner and the best trial (the oracle). A diagnostic: the fast
KL of the *baked* candidates (``lobes.tabulate(fitting.fit(table).params)``, shaded
by the fast path; what the Cycles path rendered before 2026-12-03), against both.
With two or more Cycles sample counts, the Cycles rankings are also compared with
each other (the Cycles path's own repeatability).

Writes ``bench/results/kl_agreement.json`` and ``kl_agreement.png`` (fast KL against
Cycles KL per material; ``--quick``: ``kl_agreement_quick.*``). On the loaded 2-core
machine about 1.5 minutes a material and seed with 4 and 16 Cycles samples (0.47 s
and 0.75 s a render, 48 renders each); the full run (``--seeds 3 --cycles-samples
4,16``, what ``make bench`` runs) 20 minutes, plus each capture's generation the first
time.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import common
import numpy as np

# a glossy metal and a rough dielectric, analytic and measured (bench/tradeoff.py's
# MATERIALS, on which the presets were measured); the measured two are of
# testkit.measured.one_per_class (common.pipeline_materials)
MATERIALS = ("heldout_gold_medium", "heldout_rough_plastic", "two-layer-gold",
             "specular-black-phenolic")
QUICK = ("heldout_gold_medium", "two-layer-gold")
TARGET = 0.8  # issue 15's "Done when"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help=f"{', '.join(QUICK)} only; writes kl_agreement_quick.*")
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0 to S - 1 (default 1)")
    parser.add_argument("--materials", default=None,
                        help="comma-separated held-out materials (default: "
                             f"{', '.join(MATERIALS)})")
    parser.add_argument("--cycles-samples", default=None,
                        help="Cycles samples per pixel, comma-separated (default: the "
                             "Accurate preset's kl_samples)")
    args = parser.parse_args(argv)
    from brdf_reconstruct.brdf_addon import presets

    accurate = presets.PRESETS["ACCURATE"]["kl_samples"]
    try:
        counts = ([int(s) for s in args.cycles_samples.split(",") if s]
                  if args.cycles_samples else [accurate])
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        print("error: --cycles-samples must be positive integers, e.g. 4,16", file=sys.stderr)
        return 2
    if args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return 2
    if common.measured_pack_or_error() is None:
        return 1
    allowed = common.pipeline_materials()
    if args.materials:
        materials = common.listed(args.materials, allowed, "--materials")
        if materials is None:
            return 2
    else:
        materials = list(QUICK if args.quick else MATERIALS)
    info = common.machine("2-core machine shared with other jobs, run under nice; wall "
                          "times are noisy")
    t_start = time.perf_counter()
    rows = []
    for material in materials:
        for row in run_material(material, range(args.seeds), counts):
            rows.append(row)
            for n in map(str, counts):
                a = row["cycles"][n]
                print(f"{material} seed {row['seed']} Cycles {n}: Spearman "
                      f"{a['spearman']:+.3f}, Kendall {a['kendall']:+.3f}, winners agree "
                      f"{a['winners_agree']}, "
                      f"fast winner's Cycles rank {a['fast_winner_cycles_rank']}/"
                      f"{row['trials']}; sphere error fast {row['fast']['sphere_error']:.3f}"
                      f" / Cycles {a['sphere_error']:.3f} / oracle "
                      f"{row['oracle']['sphere_error']:.3f}", flush=True)
    document = {
        "question": "Do the fast (numpy) KL and the Cycles KL rank a region's 16 trials "
                    "alike on the bunny capture (issue 15: Spearman >= 0.8)?",
        "capture": {**common.DEMO_CAPTURE, "what": "the demo's bunny capture "
                    "(testkit/capture.py): degraded scan, COLMAP model, lit EXR photos "
                    "rendered by Cycles with the true table"},
        "settings": {"preset": "BALANCED", "cycles_samples": counts,
                     "accurate_preset_cycles_samples": accurate,
                     "basis": "common.default_basis_without(material)"},
        "target_spearman": TARGET,
        "summary": summary(rows, counts),
        "rows": rows,
        "total_seconds": time.perf_counter() - t_start,
        "machine": common.machine_end(info),
    }
    stem = "kl_agreement_quick" if args.quick else "kl_agreement"
    path = common.write_json(common.RESULTS / f"{stem}.json", document, arguments=args)
    plot(rows, counts, path.with_suffix(".png"))
    print(json.dumps(document["summary"], indent=1))
    print(f"-> {path} and {path.with_suffix('.png')} ({document['total_seconds']:.0f} s)")
    return 0


def gather_capture_scene(material: str):
    """(scene, inputs, capture seconds or None): the material's cached demo capture
    applied to an empty scene as the batch entry applies a job, its photos gathered
    as the runner gathers them."""
    import bpy

    import brdf_reconstruct
    from brdf_reconstruct.brdf_addon import gathering, job

    folder, generated_s = common.ensure_capture(material)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)  # as batch.run_job
    if not hasattr(bpy.types.Scene, "brdf"):
        brdf_reconstruct.register()
    scene = bpy.context.scene
    job.apply(job.load(folder / "job.toml"), scene)
    scene.brdf.preset = "BALANCED"
    inputs, _capture = gathering.gather_capture(scene)
    return scene, inputs, generated_s


def run_material(material: str, seeds, counts) -> list[dict]:
    """One material: per seed, the pipeline's fast ranking against the Cycles ranking
    of the same trials at each of ``counts`` Cycles samples (one row per seed)."""
    from brdf_reconstruct.brdf_addon import props

    t0 = time.perf_counter()
    scene, inputs, generated_s = gather_capture_scene(material)
    s = scene.brdf
    if (s.samples, s.trials, s.kl_path) != (20, 16, "FAST"):
        raise AssertionError(f"Balanced is not 20 x 16 with the fast KL: {s.samples}, "
                             f"{s.trials}, {s.kl_path}")
    gather_s = time.perf_counter() - t0
    truth = common.heldout_table(material)
    B = common.default_basis_without(material)
    return [run_seed(material, seed, scene, inputs, props.pipeline_settings(s), truth, B,
                     counts, {"capture_generated_s": generated_s, "gather_s": gather_s})
            for seed in seeds]


def run_seed(material, seed, scene, inputs, settings, truth, B, counts, prepared) -> dict:
    """One row: the pipeline at ``seed`` and the Cycles KL of its trials."""
    import dataclasses

    from brdf_reconstruct.brdf_addon import cycles_select, prefs
    from brdf_reconstruct.core.bake import fitting, lobes
    from brdf_reconstruct.core.brdf import metrics
    from brdf_reconstruct.core.method import pipeline, selection

    s = scene.brdf
    settings = dataclasses.replace(settings, seed=seed)
    t0 = time.perf_counter()
    result = pipeline.run(B, inputs, settings)
    pipeline_s = time.perf_counter() - t0
    (region,) = [r for r in result.regions if r.status == "ok"]
    fast = np.asarray(region.kl, dtype=np.float64)
    views = pipeline.region_views(inputs, region.region)
    device = prefs.cycles_device()
    cycles = {n: [] for n in counts}
    sphere, baked_fast = [], []
    seconds = {n: 0.0 for n in counts} | {"bake_diagnostic": 0.0, "sphere_error": 0.0}
    for t in range(len(region.candidates)):
        table = np.asarray(region.candidates[t], dtype=np.float64)
        t1 = time.perf_counter()
        sphere.append(metrics.sphere_error(table, truth))
        seconds["sphere_error"] += time.perf_counter() - t1
        for n in counts:
            t1 = time.perf_counter()
            kl = cycles_select.score_candidate(scene, inputs, region.region, table, n,
                                               s.kl_bins, device=device)
            cycles[n].append(float(kl.mean()))
            seconds[n] += time.perf_counter() - t1
        t1 = time.perf_counter()
        baked = lobes.tabulate(fitting.fit(table, errors=False).params)
        baked_fast.append(float(selection.select_by_kl([baked], views,
                                                       n_bins=s.kl_bins).kl[0]))
        seconds["bake_diagnostic"] += time.perf_counter() - t1
        print(f"  {material} seed {seed} trial {t + 1}/{len(region.candidates)}: fast "
              f"{fast[t]:.4f}, fast of the baked {baked_fast[-1]:.4f}, Cycles "
              + ", ".join(f"{cycles[n][-1]:.4f} ({n})" for n in counts)
              + f"; sphere {sphere[-1]:.3f}", flush=True)
    sphere = np.array(sphere)
    baked_fast = np.array(baked_fast)
    oracle = int(np.argmin(sphere))
    row = {
        "material": material, "measured": common.is_measured(material), "seed": seed,
        "trials": len(fast), "capture_generated_s": prepared["capture_generated_s"],
        "counts": region.counts,
        "fast": {"kl": fast.tolist(), "winner": int(region.winner),
                 "sphere_error": float(sphere[region.winner])},
        "oracle": {"trial": oracle, "sphere_error": float(sphere[oracle]),
                   "fast_rank": _rank(fast, oracle)},
        "median_trial_sphere_error": float(np.median(sphere)),
        "sphere_error": sphere.tolist(),
        "fast_kl_of_baked": {"kl": baked_fast.tolist(), "winner": int(np.argmin(baked_fast)),
                             **_agreement(fast, baked_fast, "fast", "baked")},
        "cycles": {},
        "seconds": {"gather": prepared["gather_s"], "pipeline": pipeline_s,
                    **{f"cycles_{k}" if isinstance(k, int) else k: v
                       for k, v in seconds.items()}},
    }
    for n in counts:
        c = np.array(cycles[n])
        winner = int(np.argmin(c))
        row["cycles"][str(n)] = {
            "kl": c.tolist(), "winner": winner, "sphere_error": float(sphere[winner]),
            **_agreement(fast, c, "fast", "cycles"),
            "baked_fast_vs_cycles": _agreement(baked_fast, c, "baked", "cycles"),
            "oracle_cycles_rank": _rank(c, oracle),
            "seconds_per_render": seconds[n] / (len(fast) * len(views)),
        }
    if len(counts) > 1:
        a, b = counts[0], counts[-1]
        row[f"cycles_{a}_vs_{b}"] = _agreement(np.array(cycles[a]), np.array(cycles[b]),
                                               str(a), str(b))
    return row


def _rank(score: np.ndarray, i: int) -> int:
    """1-based rank of trial ``i`` under ``score`` (1 = the lowest)."""
    return int(np.count_nonzero(score < score[i])) + 1


def _agreement(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> dict:
    """Spearman and Kendall correlation of two scores of the same trials, whether their
    winners agree, and ``a``'s winner's rank under ``b``."""
    from scipy import stats

    return {"spearman": float(stats.spearmanr(a, b).statistic),
            "kendall": float(stats.kendalltau(a, b).statistic),
            "winners_agree": bool(np.argmin(a) == np.argmin(b)),
            f"{name_a}_winner_{name_b}_rank": _rank(b, int(np.argmin(a)))}


def summary(rows, counts) -> dict:
    """Per Cycles sample count: each material's median Spearman over its seeds; medians
    over rows (material x seed) of the correlations and sphere errors, the rows whose
    winners agree and the rows at the target."""
    out = {}
    materials = list(dict.fromkeys(r["material"] for r in rows))
    for n in map(str, counts):
        a = [r["cycles"][n] for r in rows]
        out[n] = {
            "per_material_median_spearman": {m: float(np.median(
                [r["cycles"][n]["spearman"] for r in rows if r["material"] == m]))
                for m in materials},
            "median_spearman": float(np.median([x["spearman"] for x in a])),
            "min_spearman": float(np.min([x["spearman"] for x in a])),
            "median_kendall": float(np.median([x["kendall"] for x in a])),
            "winners_agree": f"{sum(x['winners_agree'] for x in a)} of {len(a)}",
            "rows_at_target": f"{sum(x['spearman'] >= TARGET for x in a)} of {len(a)}",
            "median_sphere_error": {
                "fast_winner": float(np.median([r["fast"]["sphere_error"] for r in rows])),
                "cycles_winner": float(np.median([x["sphere_error"] for x in a])),
                "oracle": float(np.median([r["oracle"]["sphere_error"] for r in rows]))},
            "median_spearman_baked_fast_vs_cycles": float(np.median(
                [x["baked_fast_vs_cycles"]["spearman"] for x in a])),
        }
    out["median_spearman_fast_vs_baked_fast"] = float(np.median(
        [r["fast_kl_of_baked"]["spearman"] for r in rows]))
    return out


def plot(rows, counts, path) -> None:
    """Fast KL against Cycles KL, one panel per row: a marker per trial and Cycles
    sample count; the fast winner, the Cycles winner and the oracle marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_cols = min(len(rows), 4)
    n_rows = -(-len(rows) // n_cols)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(4.2 * n_cols, 3.8 * n_rows),
                             squeeze=False)
    for ax, row in zip(axes.flat, rows, strict=False):
        fast = np.array(row["fast"]["kl"])
        for k, n in enumerate(map(str, counts)):
            c = np.array(row["cycles"][n]["kl"])
            colour = f"C{k}"
            ax.scatter(fast, c, s=18, color=colour,
                       label=f"Cycles {n} spp: rho {row['cycles'][n]['spearman']:+.2f}, "
                             f"tau {row['cycles'][n]['kendall']:+.2f}")
            w = row["cycles"][n]["winner"]
            ax.scatter(fast[w], c[w], s=110, facecolors="none", edgecolors=colour,
                       marker="s")
        c0 = np.array(row["cycles"][str(counts[0])]["kl"])
        f, o = row["fast"]["winner"], row["oracle"]["trial"]
        ax.scatter(fast[f], c0[f], s=140, facecolors="none", edgecolors="k", marker="o",
                   label=f"fast winner ({row['fast']['sphere_error']:.3f})")
        ax.scatter(fast[o], c0[o], s=120, color="gold", edgecolors="k", marker="*",
                   zorder=3, label=f"oracle ({row['oracle']['sphere_error']:.3f})")
        ax.set_title(f"{row['material']} (seed {row['seed']})", fontsize=9)
        ax.set_xlabel("fast KL (nats)")
        ax.set_ylabel("Cycles KL (nats); square: its winner")
        ax.legend(fontsize=6.5)
    for ax in list(axes.flat)[len(rows):]:
        ax.axis("off")
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
