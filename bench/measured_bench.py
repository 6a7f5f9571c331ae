"""Bases against measured materials, cross-validated: which basis reconstructs real
(MERL) BRDFs from few samples, per fold and per material class.

    .venv/bin/python bench/measured_bench.py [--quick] [--folds K] [--bases a,b,...]
                                             [--seeds S] [--criterion C] [--out PATH]

The 80 measured materials of the pack (``testkit.measured.PACK``, Sztrajman et al.
2021 networks of MERL) are split into 5 stratified folds of 16
(``testkit.measured.folds``). For each fold, every basis is built without that
fold's materials and scored on them, so no material is scored by a basis that
saw it:

- ``analytic``: the built-in analytic database (today's default; it holds no
  measured material, so it is the same basis in every fold);
- ``measured``: PCA of the 64 other measured materials (same mapping, k = 40);
- ``union``: the analytic database and the 64 measured materials together.

Per held-out material: reconstruction (``core.method.reconstruct`` with its
defaults: p = k, eta by evidence; exact values at the cells, no photos) from
n = 6 and n = 20 optimal cells (``core.method.sampling.optimal_cells``, the
criterion ``--criterion``: ``risk``, the default, or the paper's ``condition``)
and from 2000 random cells, seeds 0 and 1 (``--seeds S``: 0 to S - 1); score:
rendered-sphere relative RMSE under four lights (``render.REFERENCE_LIGHT`` and
``metrics.SPHERE_LIGHTS``). Each cell set's condition number (``condition``) is
recorded, and per setting the median over each seed's cell sets (``per_seed``)
and the Spearman correlation, over folds x seeds, of the condition against the
fold's median error (``condition_vs_error``): does the sampler's criterion predict
the error? Writes ``bench/results/measured.json`` and ``measured.png``
(``--quick``: ``measured_quick.*``; ``--out``: that path and its ``.png``). About
40 minutes on the 2-core machine with the three bases (``--quick``: 2 folds, seed
0).
"""

from __future__ import annotations

import argparse
import functools
import json
import pathlib
import sys
import time

import common
import numpy as np

from brdf_reconstruct.core.brdf import basis, database, merl, metrics, nbrdf, render
from brdf_reconstruct.core.method import reconstruct, sampling
from testkit import measured

LIGHTS = np.vstack([render.REFERENCE_LIGHT, metrics.SPHERE_LIGHTS])
SETTINGS = (("n=6", 6, "optimal"), ("n=20", 20, "optimal"), ("2000 random", 2000, "random"))
BASES = ("analytic", "measured", "union")


def _cells(B, kind, n, seed, criterion):
    candidates = merl.cells_from_linear(B.cells)
    rng = np.random.default_rng(seed)
    if kind == "optimal":
        return sampling.optimal_cells(B, candidates, n, rng, criterion=criterion)
    return candidates[rng.choice(len(candidates), n, replace=False)]


def _spheres(table) -> np.ndarray:
    """The table on the evaluation sphere under each of :data:`LIGHTS` (what
    ``metrics.sphere_error`` renders), stacked: (K, 96, 96, 3)."""
    return np.stack([render.render_sphere(table, light, 96) for light in LIGHTS])


def _score(B, name, truth, truth_spheres, cells) -> float:
    """``metrics.sphere_error`` of material ``name``'s reconstruction, the truth
    rendered once per material instead of once per reconstruction; refused
    (``measured.held_out``) if the basis was built from the material."""
    measured.held_out(B, name)
    values = truth.reshape(3, -1)[:, merl.linear_index(cells)].T
    rec = reconstruct.reconstruct(B, cells, values)
    if not np.all(np.isfinite(rec.table[np.isfinite(truth)])):
        raise AssertionError("a reconstruction holds NaN or Inf")
    return metrics.relative_rmse(_spheres(rec.table), truth_spheres)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="2 folds, seed 0")
    parser.add_argument("--folds", type=int, default=5, help="folds of the 80 (default 5)")
    parser.add_argument("--bases", default=",".join(BASES),
                        help=f"comma-separated, of {', '.join(BASES)}")
    parser.add_argument("--seeds", type=int, default=None,
                        help="sampler seeds 0 to S - 1 (default 2; --quick 1)")
    parser.add_argument("--criterion", default="risk", choices=sampling.CRITERIA,
                        help="the sampler's criterion (default risk)")
    parser.add_argument("--out", default=None, help="JSON path (default bench/results/...)")
    args = parser.parse_args(argv)
    if args.seeds is not None and args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return 2
    bases = common.listed(args.bases, BASES, "--bases")
    if bases is None:
        return 2
    pack = common.measured_pack_or_error()
    if pack is None:
        return 1
    info = common.machine("bases against measured materials, cross-validated")
    seeds = tuple(range(args.seeds if args.seeds else 1 if args.quick else 2))
    folds = measured.folds(pack.names, k=args.folds)
    if args.quick:
        folds = folds[:2]
    analytic = basis.load_default()
    rows, builds = [], []
    t_all = time.perf_counter()
    for f, held in enumerate(folds):
        train = [n for n in pack.names if n not in held]
        built = {}
        if "analytic" in bases:
            built["analytic"] = analytic
        measured_makers = [functools.partial(nbrdf.valid_values, pack, pack.index(n))
                           for n in train]
        if "measured" in bases:
            t0 = time.perf_counter()
            built["measured"] = common.measured_basis_without(pack, held)
            builds.append({"fold": f, "basis": "measured", "tables": len(train),
                           "seconds": time.perf_counter() - t0})
        if "union" in bases:
            t0 = time.perf_counter()
            specs = database.training_specs()
            makers = [functools.partial(database.valid_values, s) for s in specs]
            built["union"] = basis.build_from(makers + measured_makers,
                                              names=[s["name"] for s in specs] + train)
            builds.append({"fold": f, "basis": "union", "tables": len(makers),
                           "seconds": time.perf_counter() - t0})
        cells = {(b, label, seed): _cells(B, kind, n, seed, args.criterion)
                 for b, B in built.items() for label, n, kind in SETTINGS for seed in seeds}
        condition = {key: sampling.acquisition_condition(
            built[key[0]].Q, built[key[0]].rows_of(merl.linear_index(c)))
            for key, c in cells.items()}
        for name in held:
            truth = nbrdf.tabulate(pack, pack.index(name))
            truth_spheres = _spheres(truth)
            for (b, label, seed), c in cells.items():
                rows.append({"fold": f, "material": name,
                             "class": measured.material_class(name), "basis": b,
                             "setting": label, "seed": seed,
                             "condition": condition[(b, label, seed)],
                             "sphere_rel_rmse": _score(built[b], name, truth, truth_spheres, c)})
        print(f"fold {f + 1}/{len(folds)} done ({time.perf_counter() - t_all:.0f} s)",
              flush=True)
        del built
    summary = {b: {label: float(np.median([r["sphere_rel_rmse"] for r in rows
                                          if r["basis"] == b and r["setting"] == label]))
                   for label, _, _ in SETTINGS} for b in bases}
    per_fold = {b: {label: [float(np.median([r["sphere_rel_rmse"] for r in rows
                                             if r["basis"] == b and r["setting"] == label
                                             and r["fold"] == f])) for f in range(len(folds))]
                    for label, _, _ in SETTINGS} for b in bases}
    per_class = {b: {k: {label: float(np.median(v)) if (v := [
        r["sphere_rel_rmse"] for r in rows if r["basis"] == b and r["setting"] == label
        and r["class"] == k]) else None for label, _, _ in SETTINGS}
        for k in measured.CLASSES} for b in bases}
    per_material = {b: {n: float(np.median([r["sphere_rel_rmse"] for r in rows
                                            if r["basis"] == b and r["material"] == n
                                            and r["setting"] == "n=20"]))
                        for n in sorted({r["material"] for r in rows})} for b in bases}
    per_seed, condition_vs_error = _seed_spread(rows, bases, len(folds), seeds)
    doc = {"machine": common.machine_end(info), "folds": folds, "seeds": list(seeds),
           "criterion": args.criterion,
           "per_seed": per_seed, "condition_vs_error": condition_vs_error,
           "lights": LIGHTS.tolist(), "summary_median_sphere_rel_rmse": summary,
           "per_fold": per_fold, "per_class": per_class, "per_material_n20": per_material,
           "builds": builds, "seconds": time.perf_counter() - t_all, "runs": rows}
    stem = "measured_quick" if args.quick else "measured"  # a quick run never replaces
    target = pathlib.Path(args.out) if args.out else common.RESULTS / f"{stem}.json"
    path = common.write_json(target, doc, arguments=vars(args))
    plot(doc, target.with_suffix(".png"))
    print(json.dumps({"summary": summary, "per_class": per_class, "per_seed": per_seed,
                      "condition_vs_error": condition_vs_error}, indent=1))
    print(f"-> {path}")
    return 0


def _seed_spread(rows, bases, n_folds, seeds):
    """Per basis and setting: the median error of each seed's cell sets, and the
    Spearman correlation over folds x seeds of a cell set's condition number against
    the fold's median error (None with fewer than 3 pairs)."""
    from scipy import stats

    per_seed, correlation = {}, {}
    for b in bases:
        per_seed[b], correlation[b] = {}, {}
        for label, _, _ in SETTINGS:
            mine = [r for r in rows if r["basis"] == b and r["setting"] == label]
            per_seed[b][label] = [float(np.median([r["sphere_rel_rmse"] for r in mine
                                                   if r["seed"] == s])) for s in seeds]
            pairs = [(next(r["condition"] for r in group), float(np.median(
                [r["sphere_rel_rmse"] for r in group])))
                for f in range(n_folds) for s in seeds
                if (group := [r for r in mine if r["fold"] == f and r["seed"] == s])]
            conditions = [c for c, _ in pairs]
            errors = [e for _, e in pairs]
            correlation[b][label] = (float(stats.spearmanr(conditions, errors)[0])
                                     if len(pairs) >= 3 else None)
    return per_seed, correlation


def plot(doc: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bases = list(doc["summary_median_sphere_rel_rmse"])
    labels = [label for label, _, _ in SETTINGS]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    width = 0.8 / len(bases)
    for i, b in enumerate(bases):
        axes[0].bar(np.arange(len(labels)) + i * width,
                    [doc["summary_median_sphere_rel_rmse"][b][x] for x in labels], width, label=b)
        classes = list(doc["per_class"][b])
        axes[1].bar(np.arange(len(classes)) + i * width,
                    [doc["per_class"][b][k]["n=20"] or 0 for k in classes], width, label=b)
    axes[0].set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels)
    axes[0].set_title("median rendered-sphere error, held-out measured materials", fontsize=9)
    axes[1].set_xticks(np.arange(len(classes)) + 0.4 - width / 2, classes)
    axes[1].set_title(f"per class, n = 20 {doc.get('criterion', 'condition')}-optimal cells",
                      fontsize=9)
    for ax in axes:
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
