"""Textured regions on the numpy scene (issue 16): the albedo per texel and the shared
BRDF shape of ``core.method.textured``, against the truth the photos were made from.

    .venv/bin/python bench/texture_bench.py [--objects numpy,spot] [--seeds S] [--quick]

Two objects. **Spot** (``--objects spot``): the capture of ``bench/photo_bench.py``
(``capture_arrays``: three lit views of 240 x 180, photos shaded on the truth's
Cycles G-buffers, the degraded "photogrammetry" mesh as the scan, or the truth's
own G-buffers, "exact"), with Spot's own UV map (which the degraded mesh keeps)
and a 64 x 64 texture of 8-texel patches (``--registration``: on the truth's UV map,
which the degraded scan's interpolated UVs misregister, or on the scan's, as a
photogrammetry texture is baked onto the scan). **The numpy scene** (``numpy``): the
tests' height field (``testkit.synthetic``, 96 x 96 pixels, an
orthographic camera, three distant lights, 1 % photo noise), its UV map the plane's
(x, y), and a 24 x 24 texture of 4-texel patches times a 1-texel checker
(``synthetic.patch_texture``, 17:1 or more, a new draw per seed). The scan is the
truth's own G-buffers ("exact") or the blunted height field ("blunted", a 3-pixel
Gaussian and noise, as ``tests/core/method/test_pipeline.py``'s).

What the texture scales, the truth (independent of the estimator's model):
- the analytic held-out materials with a Lambert or Oren-Nayar lobe: that lobe,
  under the coat where there is one (``synthetic.colour_tables``), "diffuse";
- the analytic metals and the measured materials (one per class), whose split is
  unknown: the whole table, "whole" (a tinted metal, rust).

Per material, scan and seed, with Balanced's settings (20 samples x 16 trials, fast
KL) and the default basis without the material (``common.default_basis_without``):
- ``albedo_error``: the median over measured texels of the relative error of the
  texture's pattern (the estimate and the truth each over their mean on those texels);
  ``albedo_error_floor``: the same with the true table as the shared shape (what the
  scan's normals alone cost);
- ``sphere``: the rendered-sphere error (``metrics.sphere_error``) of the shared
  shape (``textured``: against the true table at the same reference color, the
  true texture's mean over the measured texels in the part the texture scales, as
  only the product of table and texture is observed; ``textured_against_mean_1``:
  against the table at the texture's mean over all texels, as before 2026-12-04),
  of the method on the same photos untextured (``untextured``:
  the photos made with a texture of 1) and on the textured photos as they are
  (``naive``);
- the model chosen, whether the region got a constant, the fits made, seconds;
- ``with_scan_texture``: the same textured run given the scan's own texture as
  the prior, as the extension runs (``testkit.scan_texture``, a photogrammetry
  bake simulated with the ambient occlusion and the sky's reflection): its albedo
  errors (``albedo_error`` over the measured texels, ``albedo_error_seen`` over
  every texel a lit photo observes, as issue 16 asks) and sphere error, the
  texture's own pattern error, the prior's weighing and agreement (``core.method.albedo``)
  and, where the region was settled both with it and with the photos' own texture,
  how they compared (``choice``, ``core.method.textured.run``).
  ``--prior truth`` gives the true texture in its place (an oracle, its own error 0):
  what the textured path costs where the colour is known, so that the shared
  shape's gap to the untextured capture splits into the scan texture's share and
  the method's (``texture_truth_prior.*``).

Writes ``bench/results/texture.json`` and ``texture.png`` (``--quick``:
``texture_quick.*``, 4 materials). About 34 minutes per seed on the 2-core machine.
``--scans exact`` (or ``blunted``) runs one scan and writes ``texture_exact.*``.
``--rows FILE [FILE ...]`` runs nothing: it summarises the rows of earlier runs
(their result files, or JSON lists of rows), e.g. of the objects run side by side in
two worktrees; the rows are written as they are, in the order given (``minutes``
then None).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import common
import numpy as np

from brdf_reconstruct.core.brdf import metrics
from brdf_reconstruct.core.method import albedo, pipeline, textured
from testkit import synthetic
from testkit.scan_texture import numpy_arrays, scan_texture

RES = 96
SHAPE = (24, 24)
SETTINGS = dict(n_samples=20, n_trials=16)  # Balanced's
SCANS = ("exact", "blunted")
SPOT_SHAPE = (64, 64)
OBJECTS = ("numpy", "spot")


def truth_parts(name: str):
    """(colour part, rest, kind) of a material's table: what its texture scales."""
    table = common.heldout_table(name)
    if not common.is_measured(name):
        colour, rest = synthetic.colour_tables(common.heldout_spec(name))
        if np.nanmax(colour) > 0.0:
            return colour, rest, "diffuse"
    return table, np.zeros_like(table), "whole"


def scene(scan: str):
    z = synthetic.height_field(RES)
    truth = synthetic.gbuffer_from_heights(z)
    seen = truth if scan == "exact" else synthetic.gbuffer_from_heights(
        synthetic.blunted(z, rng=1))
    return truth, seen


def inputs(colour, rest, texture, truth, seen, seed: int):
    return synthetic.textured_inputs(colour, rest, texture, SHAPE, truth, seen,
                                     rng_base=100 * seed)


def spot_arrays(light=None) -> dict:
    """Spot's capture arrays with UVs: {"exact": ..., "blunted": ...} (the degraded
    scan), under ``light`` (world, towards it; default ``capture_arrays.LIGHT``)."""
    import capture_arrays
    import photo_bench

    from testkit import measured

    light = capture_arrays.LIGHT if light is None else tuple(light)
    degraded = capture_arrays.gbuffers(mesh=measured.DATA / "spot.obj", uv=True, light=light)
    degraded["ambient"] = capture_arrays.ambient_shading(mesh=measured.DATA / "spot.obj")
    exact = photo_bench.exact_scan(degraded)
    exact["scan_uv"] = degraded["truth_uv"]
    exact["ambient"] = degraded["ambient"]
    return {"exact": exact, "blunted": degraded}


def one(name: str, scan: str, seed: int, spot: dict | None = None,
        registration: str = "truth", prior_kind: str = "scan") -> dict:
    basis = common.default_basis_without(name)
    table = common.heldout_table(name)
    colour, rest, kind = truth_parts(name)
    shape = SHAPE if spot is None else SPOT_SHAPE
    tex = synthetic.patch_texture(shape, patch=4 if spot is None else 8, seed=seed)
    if spot is None:
        truth, seen = scene(scan)
        arrays = numpy_arrays(truth, seen)

        def make(texture):
            return inputs(colour, rest, texture, truth, seen, seed)
    else:
        arrays = spot[scan]
        import capture_arrays

        def make(texture):
            return capture_arrays.textured_photo_inputs(spot[scan], colour, rest, texture,
                                                        shape, noise=0.01, seed=seed,
                                                        texel_uv=registration)
    settings = pipeline.PipelineSettings(seed=seed, **SETTINGS)
    flat = pipeline.run(basis, make(np.ones_like(tex)), settings).regions[0]
    photos = make(tex)
    naive = pipeline.run(basis, photos, settings).regions[0]
    t0 = time.perf_counter()
    result = textured.run(basis, photos, settings, textured.TextureSettings(shape=shape))
    seconds = time.perf_counter() - t0
    region = result.result.regions[0]
    t = result.textures[0]
    measured = t.map.measured
    prior = tex if prior_kind == "truth" else scan_texture(
        arrays, colour, rest, tex, shape, arrays["ambient"],
        registration=registration if spot is not None else "truth", seed=seed)
    with_prior = textured.run(basis, photos, settings, textured.TextureSettings(shape=shape),
                              prior=prior)
    tp = with_prior.textures[0]
    seen_p = tp.map.measured & np.isfinite(prior.reshape(-1, 3)).all(1)
    # the shared table is at the region's reference color, the mean albedo over the
    # measured texels (core.method.albedo): only the product of table and texture is
    # observed, so its truth is the true table with the true texture's mean over the
    # same texels in the part the texture scales
    mean = tex[measured].mean(axis=0) if measured.any() else np.ones(3)
    at_reference = rest + colour * mean[:, None, None, None]
    floor = _floor(table, photos, tex, shape)
    mean_p = tex[tp.map.measured].mean(axis=0)
    return {
        "object": "numpy" if spot is None else "spot", "material": name, "scan": scan,
        "registration": registration if spot is not None else "truth",
        "seed": seed, "truth": kind, "model": t.model,
        "constant": bool(t.map.constant), "reason": t.map.reason,
        "measured_texels": int(measured.sum()),
        "albedo_error": pattern_error(t, tex), "albedo_error_floor": floor,
        "with_scan_texture": {
            "albedo_error": pattern_error(tp, tex),
            "albedo_error_seen": seen_error(tp, tex),
            "scan_texture_error": _relative_pattern_error(prior.reshape(-1, 3)[seen_p],
                                                          tex[seen_p]),
            "sphere": metrics.sphere_error(with_prior.result.regions[0].table,
                                           rest + colour * mean_p[:, None, None, None]),
            "constant": bool(tp.map.constant), "model": tp.model,
            "pattern": tp.map.stats["pattern"],
            "weighting": tp.map.stats.get("prior_weighting"),
            "agreement": tp.map.stats.get("prior_agreement"), "choice": tp.choice},
        "sphere": {"textured": metrics.sphere_error(region.table, at_reference),
                   "textured_against_mean_1": metrics.sphere_error(region.table, table),
                   "untextured": metrics.sphere_error(flat.table, table),
                   "naive": metrics.sphere_error(naive.table, table)},
        "fits": len(result.rounds), "seconds_textured": seconds,
    }


def pattern_error(t: textured.RegionTexture, tex: np.ndarray) -> float:
    """The median over measured texels (``AlbedoMap.measured``: the data alone give
    them, whether or not the value is the data's) of the relative error of the
    texture's pattern (estimate and truth each over their mean on those texels)."""
    measured = t.map.measured
    return _relative_pattern_error(t.relative()[measured], tex[measured])


def seen_error(t: textured.RegionTexture, tex: np.ndarray) -> float:
    """As :func:`pattern_error` over every texel a lit photo observes
    (``AlbedoMap.observations`` > 0), whatever its coverage: measured, or the scan's
    texture kept where the photos could not tell it from one colour."""
    seen = t.map.observations > 0
    return _relative_pattern_error(t.relative()[seen], tex[seen])


def _relative_pattern_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    """The median relative error of a pattern, each over its mean ((T, 3) both)."""
    est = estimate / estimate.mean(axis=0)
    true = truth / truth.mean(axis=0)
    return float(np.median(np.abs(est - true) / true))


def _floor(table, photos, tex, shape) -> float:
    """The albedo error with the true table as the shared shape: what the scan's
    normals alone cost (``textured.estimate_texture`` on the same observations)."""
    raw, _ = pipeline.observe_photos(photos, pipeline.PipelineSettings())
    texel = textured.sample_texels(raw, [p.uv for p in photos], shape)
    at = np.flatnonzero((texel >= 0) & (raw.region == 0))
    t = textured.estimate_texture(table, raw.subset(at), texel[at], shape,
                                  albedo.AlbedoSettings())
    return pattern_error(t, tex)


def summarise(rows: list) -> dict:
    return {obj: _summarise([r for r in rows if r["object"] == obj]) for obj in OBJECTS
            if any(r["object"] == obj for r in rows)}


def _summarise(rows: list) -> dict:
    out = {}
    for scan in SCANS:
        part = [r for r in rows if r["scan"] == scan]
        if not part:
            continue
        by = {}
        for r in part:
            by.setdefault(r["material"], []).append(r)

        def med(key, sub=None, group=None, by=by):
            values = [np.median([x[key][sub] if sub else x[key] for x in v])
                      for v in by.values() if group is None or v[0]["truth"] == group]
            return float(np.median(values)) if values else None

        ratios = [np.median([x["sphere"]["textured"] / x["sphere"]["untextured"] for x in v])
                  for v in by.values()]
        out[scan] = {
            "materials": len(by),
            "albedo_error_median": med("albedo_error"),
            "albedo_error_floor_median": med("albedo_error_floor"),
            "albedo_error_median_diffuse_truth": med("albedo_error", group="diffuse"),
            "albedo_error_median_whole_truth": med("albedo_error", group="whole"),
            "sphere_textured": med("sphere", "textured"),
            "sphere_untextured": med("sphere", "untextured"),
            "sphere_naive": med("sphere", "naive"),
            "ratio_textured_over_untextured_median": float(np.median(ratios)),
            "within_1_3x": int(sum(r <= 1.3 for r in ratios)),
            "model_matches_truth": int(sum(v[0]["model"] == v[0]["truth"] for v in by.values())),
        }
        prior_ratios = [np.median([x["with_scan_texture"]["sphere"] / x["sphere"]["untextured"]
                                   for x in v]) for v in by.values()]
        out[scan]["with_scan_texture"] = {
            "albedo_error_median": float(np.median([np.median(
                [x["with_scan_texture"]["albedo_error"] for x in v]) for v in by.values()])),
            "albedo_error_seen_median": float(np.median([np.median(
                [x["with_scan_texture"]["albedo_error_seen"] for x in v]) for v in by.values()])),
            "albedo_error_at_most_10_percent": int(sum(np.median(
                [x["with_scan_texture"]["albedo_error"] for x in v]) <= 0.10
                for v in by.values())),
            "scan_texture_error_median": float(np.median([np.median(
                [x["with_scan_texture"]["scan_texture_error"] for x in v])
                for v in by.values()])),
            "sphere_textured": float(np.median([np.median(
                [x["with_scan_texture"]["sphere"] for x in v]) for v in by.values()])),
            "ratio_textured_over_untextured_median": float(np.median(prior_ratios)),
            "within_1_3x": int(sum(r <= 1.3 for r in prior_ratios)),
            "constant": int(sum(v[0]["with_scan_texture"]["constant"] for v in by.values())),
        }
    return out


def plot(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r["material"] for r in rows})
    objects = [o for o in OBJECTS if any(r["object"] == o for r in rows)]
    fig, axes = plt.subplots(len(objects), 2, figsize=(12, 4.5 * len(objects)), squeeze=False)
    for i, obj in enumerate(objects):
        for k, scan in enumerate(SCANS):
            ax = axes[i, k]
            for j, key in enumerate(("untextured", "naive", "textured")):
                values = [np.median([r["sphere"][key] for r in rows if r["material"] == m
                                     and r["scan"] == scan and r["object"] == obj] or [np.nan])
                          for m in names]
                ax.bar(np.arange(len(names)) + 0.27 * (j - 1), values, 0.27, label=key)
            ax.set_yscale("log")
            ax.set_title(f"{obj}, {scan} scan: sphere error of the shared shape", fontsize=9)
            ax.set_xticks(range(len(names)))
            ax.set_xticklabels([n.replace("heldout_", "") for n in names], rotation=70,
                               fontsize=7)
            ax.legend(fontsize=8)
    common.save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", default="numpy,spot")
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--quick", action="store_true", help="4 materials")
    parser.add_argument("--rows", nargs="+", metavar="FILE",
                        help="summarise the rows of these earlier runs' files instead of "
                        "running")
    parser.add_argument("--scans", default=",".join(SCANS),
                        help="the scans to run, of exact,blunted (fewer than both: "
                        "writes texture_<scan>.*)")
    parser.add_argument("--prior", choices=("scan", "truth"), default="scan",
                        help="the texture given as the scan's: its simulated bake (default) "
                        "or the true texture, an oracle that measures what the textured "
                        "path costs where the colour is known (writes texture_truth_prior.*)")
    parser.add_argument("--registration", choices=("truth", "scan"), default="truth",
                        help="Spot's texture on the truth's UV map (default; the degraded "
                        "scan's UVs misregister it) or on the scan's, as a photogrammetry "
                        "texture is baked (writes texture_scan_registered.*)")
    args = parser.parse_args(argv)
    objects = common.listed(args.objects, OBJECTS, "--objects")
    scans = common.listed(args.scans, SCANS, "--scans")
    if objects is None or scans is None:
        return 2
    if args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return 2
    if common.measured_pack_or_error() is None:
        return 1
    info = common.machine()
    materials = common.pipeline_materials()
    if args.quick:
        materials = ["heldout_glossy_plastic", "heldout_lambert_grey", "heldout_gold_medium",
                     materials[-1]]
    rows = []
    t0 = time.perf_counter()
    for path in args.rows or ():  # earlier runs' rows: summarised, nothing run
        loaded = json.loads(pathlib.Path(path).read_text())
        rows += loaded["rows"] if isinstance(loaded, dict) else loaded
    cases = [] if args.rows else [(o, n, sc, sd) for o in objects for n in materials
                                  for sc in scans for sd in range(args.seeds)]
    spot = spot_arrays() if any(c[0] == "spot" for c in cases) else None
    given = "the true texture" if args.prior == "truth" else "the scan's texture"
    for obj, name, scan, seed in cases:
        rows.append(one(name, scan, seed, spot if obj == "spot" else None,
                        args.registration, args.prior))
        r = rows[-1]
        w = r["with_scan_texture"]
        print(f"{obj} {name} {scan} seed {seed}: albedo {r['albedo_error']:.3f} "
              f"(with {given} {w['albedo_error']:.3f}, the texture itself "
              f"{w['scan_texture_error']:.3f}, sphere {w['sphere']:.3f}) "
              f"(floor {r['albedo_error_floor']:.3f}) ({r['model']}, truth {r['truth']}), "
              f"sphere {r['sphere']['textured']:.3f} / {r['sphere']['untextured']:.3f} "
              f"untextured / {r['sphere']['naive']:.3f} naive, {r['fits']} fits, "
              f"{r['seconds_textured']:.1f} s", flush=True)
    stem = "texture_quick" if args.quick else "texture"
    if args.registration == "scan":
        stem += "_scan_registered"
    if args.prior == "truth":
        stem += "_truth_prior"
    if len(scans) < len(SCANS):
        stem += "_" + "_".join(scans)
    minutes = None if args.rows else (time.perf_counter() - t0) / 60
    document = {"machine": common.machine_end(info), "minutes": minutes,
                "settings": {"resolution": RES, "texture": list(SHAPE), "noise": 0.01,
                             "photos": 3, **SETTINGS, "seeds": args.seeds},
                "summary": summarise(rows), "rows": rows}
    common.write_json(common.RESULTS / f"{stem}.json", document, arguments=vars(args))
    plot(rows, common.RESULTS / f"{stem}.png")
    print(document["summary"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
