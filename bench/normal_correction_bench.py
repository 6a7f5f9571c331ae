"""Would a smooth, multi-view-consistent normal correction pay? Its upper bound (issue 15).
Writes ``bench/results/normal_correction.json`` and ``normal_correction.png``.

Run::

    export BRDF_RECONSTRUCT_CACHE=/work/main/.cache
    .venv/bin/python bench/normal_correction_bench.py           # about 15 minutes
    .venv/bin/python bench/normal_correction_bench.py --quick   # 5 materials

Issue 15 asks for the scan's normals to be refined from the lit photos "if
measurement says it pays": a smooth correction, consistent across the views.
Before building the estimator from the photos, this bench measures the best any
such correction can do: the correction is fitted to the *true* normals (an
oracle no capture has), and the photo pipeline then runs on the corrected scan.
A correction estimated from three photos under one light can only do worse
(a Lambertian pixel constrains one of a normal's two degrees of freedom).

The correction: a field of small rotations ``omega(x)`` (radians, world frame)
trilinear over a ``G^3`` grid spanning the scan's visible positions, so one
surface point gets one correction in every view (multi-view consistent) and its
smoothness is set by ``G``. A scan normal ``n`` becomes ``normalise(n + omega(x) x n)``.
The nodes' rotations are the linear least-squares fit (``scipy.sparse.linalg.lsqr``,
damping 1e-3) of ``omega(x) x n`` to ``t - n`` over the pixels the truth and
the scan both cover (``t`` the true normal). G = 16 and 32 are the scan's
smooth scales (the object has unit radius: nodes 0.13 and 0.065 apart).

Can the photos find that correction? ``photo_fit_16``: the same G = 16 field fitted
to the photos instead (Gauss-Newton on the log of each pixel's radiance summed over
the channels, Huber weights at 0.1, a grid-Laplacian smoothness term, LSQR steps
damped by 0.3; the radiance's gradient in the normal by 1-degree finite differences
of the trilinear table lookup) with the *true* BRDF given: the best case of an
alternation with the BRDF, for four materials (``PHOTO_FIT``), normal error and
pipeline alike. It is circular (the truth shapes the normals the pipeline then
reads), so it bounds an alternation from above. ``alternated_16``: the honest
round, the field fitted with Balanced's own table from the uncorrected scan,
then Balanced on the corrected scan.

``--field height`` (writes ``normal_correction_height.json`` / ``.png``): an
integrable correction instead, the surface gradient of a height field ``h(x)``
trilinear over the same kind of grid (``n`` becomes ``normalise(n - (I - n n^T)
grad h)``: one degree of freedom per node, and the corrected normals the
gradient field of a displaced surface, so one light's shading constrains it, as
in shape from shading). Its smoothness is a second-difference term on ``h``
(weight ``HEIGHT_SMOOTHNESS``) at G = 32 (``HEIGHT_GRID``); the same Gauss-Newton
fit. For every material: ``oracle_h32`` (fitted to the true normals),
``photo_fit_h32`` (to the photos with the true BRDF: the bound), ``alternated_h32``
and ``alternated2_h32`` (one and two honest rounds: Balanced's own table from the
scan, then the table of Balanced on the scan corrected with it).

Scene and scoring are ``bench/photo_bench.py``'s: the blunted bunny and Spot
(``bench/capture_arrays.py``), 3 lit photos with 1 % noise, the 12 analytic and 7
measured held-out materials, each reconstructed with a basis without it, the
Balanced settings (``PipelineSettings()`` defaults), seed 0. Per scan: the
normals' angular error against the truth (median and 90th percentile, degrees),
and per material the rendered-sphere error, the self-consistency and the energy.
"""
from __future__ import annotations

import json
import sys
import time

import capture_arrays
import common
import numpy as np
import photo_bench
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from brdf_reconstruct.core.method import pipeline
from testkit import measured

GRIDS = (16, 32)
DAMPING = 1e-3
# photo_fit_16: materials (diffuse, two glossy, a metal), iterations, smoothness weight
PHOTO_FIT = ("heldout_lambert_grey", "purple-paint", "two-layer-gold", "heldout_gold_medium")
PHOTO_FIT_ITERATIONS = 4
PHOTO_FIT_SMOOTHNESS = 1.0
# --field height: the grid and the second-difference weight (chosen on the true-BRDF fits
# of three materials, G 16 / 32 / 64 and weights 0.1 to 1000, both objects)
HEIGHT_GRID = 32
HEIGHT_SMOOTHNESS = 100.0
HEIGHT_ITERATIONS = 8


def rotation_field(x, n, G: int, lo, hi) -> sp.csr_matrix:
    """The (3N, 3 G^3) matrix taking the grid's node rotations to ``omega(x) x n``.

    x: (N, 3) positions (scene units); n: (N, 3) unit normals; lo, hi: (3,) the grid's
    corners. Trilinear weights; positions outside the box take its nearest face.
    """
    u = np.clip((x - lo) / (hi - lo), 0.0, 1.0) * (G - 1)
    i0 = np.minimum(np.floor(u).astype(np.int64), G - 2)
    f = u - i0
    N = len(n)
    # omega x n = -[n]_x omega: the cross-product matrix of n, negated
    cross = np.zeros((N, 3, 3))
    cross[:, 0, 1], cross[:, 0, 2] = n[:, 2], -n[:, 1]
    cross[:, 1, 0], cross[:, 1, 2] = -n[:, 2], n[:, 0]
    cross[:, 2, 0], cross[:, 2, 1] = n[:, 1], -n[:, 0]
    corners = np.array([(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    w = np.prod(np.where(corners[None], f[:, None], 1.0 - f[:, None]), axis=-1)  # (N, 8)
    node = (((i0[:, None, 0] + corners[:, 0]) * G + i0[:, None, 1] + corners[:, 1]) * G
            + i0[:, None, 2] + corners[:, 2])  # (N, 8)
    rows = np.broadcast_to((3 * np.arange(N))[:, None, None, None]
                           + np.arange(3)[None, None, :, None], (N, 8, 3, 3))
    cols = np.broadcast_to(3 * node[:, :, None, None] + np.arange(3)[None, None, None, :],
                           (N, 8, 3, 3))
    vals = w[:, :, None, None] * cross[:, None]
    return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())),
                         shape=(3 * N, 3 * G ** 3))


def height_field(x, n, G: int, lo, hi) -> sp.csr_matrix:
    """The (3N, G^3) matrix taking the grid's node heights (scene units) to the normals'
    change ``-(I - n n^T) grad h(x)`` (the surface gradient of the trilinear ``h``).

    x: (N, 3) positions (scene units); n: (N, 3) unit normals; lo, hi: (3,) the grid's
    corners. Positions outside the box take its nearest face.
    """
    size = np.asarray(hi, np.float64) - lo
    u = np.clip((x - lo) / size, 0.0, 1.0) * (G - 1)
    i0 = np.minimum(np.floor(u).astype(np.int64), G - 2)
    f = u - i0
    N = len(n)
    corners = np.array([(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    weight = np.where(corners[None], f[:, None], 1.0 - f[:, None])  # (N, 8, 3) per axis
    sign = np.where(corners, 1.0, -1.0)  # (8, 3): d weight / d f
    grad = np.stack([weight[:, :, (k + 1) % 3] * weight[:, :, (k + 2) % 3] * sign[None, :, k]
                     * (G - 1) / size[k] for k in range(3)], axis=-1)  # (N, 8, 3)
    tangential = np.eye(3)[None] - n[:, :, None] * n[:, None, :]  # (N, 3, 3)
    vals = -np.einsum("nij,ncj->nci", tangential, grad)  # (N, 8, 3)
    node = (((i0[:, None, 0] + corners[:, 0]) * G + i0[:, None, 1] + corners[:, 1]) * G
            + i0[:, None, 2] + corners[:, 2])  # (N, 8)
    rows = np.broadcast_to((3 * np.arange(N))[:, None, None] + np.arange(3), (N, 8, 3))
    cols = np.broadcast_to(node[:, :, None], (N, 8, 3))
    return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * N, G ** 3))


def second_differences(G: int) -> sp.csr_matrix:
    """The second differences of a scalar G^3 grid: along x, y and z, and the mixed ones
    (sqrt(2) x the first differences along two axes), stacked (rows, G^3)."""
    d1 = sp.diags([np.ones(G - 1), -np.ones(G - 1)], [0, 1], shape=(G - 1, G))
    d2 = sp.diags([np.ones(G - 2), -2.0 * np.ones(G - 2), np.ones(G - 2)], [0, 1, 2],
                  shape=(G - 2, G))
    eye = sp.identity(G)

    def along(ops):
        return sp.kron(sp.kron(ops[0], ops[1]), ops[2])

    blocks = [along([d2 if k == axis else eye for k in range(3)]) for axis in range(3)]
    blocks += [np.sqrt(2.0) * along([d1 if k in pair else eye for k in range(3)])
               for pair in ((0, 1), (0, 2), (1, 2))]
    return sp.vstack(blocks).tocsr()


def scan_grid(arrays: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scan's pixels a correction applies to, (V, H, W) bool (region >= 0, finite
    normal), and the grid's corners lo, hi (3,): their positions' box, 1e-6 wider."""
    seen = ((arrays["scan_region"] >= 0)
            & np.all(np.isfinite(arrays["scan_normal"]), axis=-1))
    x = arrays["scan_position"][seen].astype(np.float64)
    return seen, x.min(axis=0) - 1e-6, x.max(axis=0) + 1e-6


def with_field(arrays: dict, omega, G: int, field=rotation_field) -> dict:
    """The capture with every scan normal of :func:`scan_grid`'s pixels moved by the
    grid-G field ``omega`` (3 G^3, node rotations, for :func:`rotation_field`; G^3 node
    heights for :func:`height_field`) and normalised; the rest as it was."""
    seen, lo, hi = scan_grid(arrays)
    sn = arrays["scan_normal"]
    n = sn[seen].astype(np.float64)
    x = arrays["scan_position"][seen].astype(np.float64)
    fixed = n + (field(x, n, G, lo, hi) @ omega).reshape(-1, 3)
    fixed /= np.linalg.norm(fixed, axis=-1, keepdims=True)
    out = dict(arrays)
    out["scan_normal"] = sn.copy()
    out["scan_normal"][seen] = fixed.astype(sn.dtype)
    return out


def oracle_corrected(arrays: dict, G: int, field=rotation_field) -> dict:
    """The capture with its scan normals corrected by the grid-G field (rotations, or
    :func:`height_field`) fitted to the true normals (the bound of any correction that
    smooth)."""
    seen, lo, hi = scan_grid(arrays)
    both = seen & arrays["truth_mask"] & np.all(np.isfinite(arrays["truth_normal"]), axis=-1)
    n = arrays["scan_normal"][both].astype(np.float64)
    t = arrays["truth_normal"][both].astype(np.float64)
    A = field(arrays["scan_position"][both].astype(np.float64), n, G, lo, hi)
    omega = spl.lsqr(A, (t - n).ravel(), damp=DAMPING, iter_lim=500)[0]
    return with_field(arrays, omega, G, field)


def grid_laplacian(G: int) -> sp.csr_matrix:
    """(3 * 3 G^2 (G - 1), 3 G^3): the differences of each rotation component between
    grid neighbours along x, y and z (a first-difference smoothness operator)."""
    idx = np.arange(G ** 3).reshape(G, G, G)
    first, second = [], []
    for axis in range(3):
        a = np.moveaxis(idx, axis, 0)
        first.append(a[:-1].ravel())
        second.append(a[1:].ravel())
    i0, i1 = np.concatenate(first), np.concatenate(second)
    m = len(i0)
    rows = np.concatenate([np.arange(3 * m)] * 2)
    cols = np.concatenate([(3 * i0[:, None] + np.arange(3)).ravel(),
                           (3 * i1[:, None] + np.arange(3)).ravel()])
    vals = np.concatenate([np.ones(3 * m), -np.ones(3 * m)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * m, 3 * G ** 3))


def photo_fitted(arrays: dict, inputs, table, G: int = 16, field=rotation_field) -> dict:
    """The capture with its scan normals corrected by the grid-G field (rotations with a
    first-difference smoothness, or :func:`height_field` with :func:`second_differences`)
    fitted to the photos (``inputs``, ``pipeline.PhotoInput``) with ``table``
    (3, 90, 90, 180) as the BRDF (see the module docstring)."""
    from brdf_reconstruct.core.brdf import render

    light = np.asarray(arrays["light"], dtype=np.float64)
    seen, lo, hi = scan_grid(arrays)
    n0, x, v, radiance = [], [], [], []
    for i, p in enumerate(inputs):
        m = seen[i] & np.all(np.isfinite(p.photo), axis=-1) & (np.asarray(p.visibility) > 0.5)
        n0.append(p.normal[m])
        x.append(p.position[m])
        radiance.append(p.photo[m].sum(axis=1))
        v.append(render.view_directions(np.asarray(p.camera_center, np.float64), p.position[m]))
    n0, x, v = (np.concatenate(a).astype(np.float64) for a in (n0, x, v))
    radiance = np.concatenate(radiance).astype(np.float64)
    eps = 1e-3 * np.median(radiance)
    y = np.log(radiance + eps)

    def log_radiance(n):
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
        return np.log(render.shade(table, n, light, v, interpolation="trilinear").sum(axis=1)
                      + eps)

    A = field(x, n0, G, lo, hi)
    per_pixel = sp.csr_matrix((np.ones(3 * len(n0)), (np.repeat(np.arange(len(n0)), 3),
                                                       np.arange(3 * len(n0)))))
    height = field is height_field
    lap = (np.sqrt(HEIGHT_SMOOTHNESS) * second_differences(G) if height
           else np.sqrt(PHOTO_FIT_SMOOTHNESS) * grid_laplacian(G))
    omega = np.zeros(A.shape[1])
    delta = np.radians(1.0)
    for _ in range(HEIGHT_ITERATIONS if height else PHOTO_FIT_ITERATIONS):
        n = n0 + (A @ omega).reshape(-1, 3)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        f0 = log_radiance(n)
        r = y - f0
        w = np.sqrt(np.minimum(1.0, 0.1 / np.maximum(np.abs(r), 1e-12)))  # Huber
        t1 = np.cross(n, [0.3, 0.5, 0.8])
        t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
        t2 = np.cross(n, t1)
        grad = ((log_radiance(n + delta * t1) - f0)[:, None] * t1
                + (log_radiance(n + delta * t2) - f0)[:, None] * t2) / delta  # (N, 3)
        J = sp.diags(w) @ (per_pixel @ (sp.diags(grad.ravel()) @ A))
        step = spl.lsqr(sp.vstack([J, lap]), np.concatenate([w * r, -(lap @ omega)]),
                        damp=0.3, iter_lim=300)[0]
        omega = omega + step
    return with_field(arrays, omega, G, field)


def normal_error(arrays: dict) -> dict:
    """Median and 90th percentile (degrees) of the scan normals' angle to the truth's."""
    sn, tn = arrays["scan_normal"], arrays["truth_normal"]
    both = ((arrays["scan_region"] >= 0) & arrays["truth_mask"]
            & np.all(np.isfinite(sn), axis=-1) & np.all(np.isfinite(tn), axis=-1))
    cos = np.sum(sn[both].astype(np.float64) * tn[both], axis=-1)
    deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return {"median_deg": float(np.median(deg)), "p90_deg": float(np.percentile(deg, 90))}


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    height = False
    if "--field" in argv:  # the one option of this bench's own
        i = argv.index("--field")
        value = argv[i + 1] if i + 1 < len(argv) else ""
        if value not in ("rotation", "height"):
            print("error: --field must be rotation or height", file=sys.stderr)
            return 2
        height = value == "height"
        del argv[i:i + 2]
    args, objects = common.pipeline_bench_arguments(__doc__, argv, 1, "5 materials")
    if args is None:
        return objects
    if height:
        return main_height(args, objects)
    info = common.machine("the bound of a smooth normal correction, issue 15")
    t_start = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    rows, scans_info = [], {}
    for obj in objects:
        degraded = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                           else measured.DATA / "spot.obj")
        scans = {"scan": degraded}
        scans.update({f"oracle_{G}": oracle_corrected(degraded, G) for G in GRIDS})
        scans["exact"] = photo_bench.exact_scan(degraded)
        scans_info[obj] = {k: normal_error(a) for k, a in scans.items()}
        print(obj, json.dumps(scans_info[obj]), flush=True)
        for name in names:
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for seed in range(args.seeds):
                these = dict(scans)
                if name in PHOTO_FIT:  # the same photos (seed), fitted with the true BRDF
                    photos = capture_arrays.photo_inputs(degraded, truth, noise=0.01, seed=seed)
                    these["photo_fit_16"] = photo_fitted(degraded, photos, truth, 16)
                    # one round of the alternation: the field fitted with Balanced's own
                    # table from the uncorrected scan, then Balanced again
                    own = pipeline.run(B, photos, pipeline.PipelineSettings(seed=seed),
                                       regions=[0]).regions[0].table
                    these["alternated_16"] = photo_fitted(degraded, photos, own, 16)
                    for key in ("photo_fit_16", "alternated_16"):
                        scans_info[obj].setdefault(key, {})[f"{name}/{seed}"] = \
                            normal_error(these[key])
                for scan, arrays in these.items():
                    inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
                    rows.append(_balanced_row(obj, name, seed, scan, B, arrays, inputs,
                                              truth)[0])
                print(f"{obj} {name} seed {seed}: " + ", ".join(
                    f"{r['scan']} {r['sphere']:.3f}" for r in rows[-len(these):]), flush=True)
    doc = {"machine": common.machine_end(info), "materials": names,
           "seeds": list(range(args.seeds)), "grids": list(GRIDS), "damping": DAMPING,
           "settings": "Balanced (PipelineSettings() defaults), 3 photos, 1 % noise",
           "minutes": (time.perf_counter() - t_start) / 60.0,
           "normals": scans_info, "summary": summary(rows, objects), "runs": rows}
    path = common.RESULTS / ("normal_correction_quick.json" if args.quick
                             else "normal_correction.json")
    common.write_json(path, doc, arguments=vars(args))
    plot(doc, path.with_suffix(".png"))
    print(json.dumps(doc["summary"], indent=1))
    print(f"-> {path}")
    return 0


def main_height(args, objects) -> int:
    """``--field height``: the integrable correction's oracle, its bound with the true
    BRDF, and one and two honest rounds, for every material (the module docstring)."""
    info = common.machine("an integrable (height-field) normal correction, issue 15")
    t_start = time.perf_counter()
    names = common.pipeline_materials(args.quick)
    G = HEIGHT_GRID
    rows, scans_info = [], {}
    for obj in objects:
        degraded = capture_arrays.gbuffers(mesh=None if obj == "bunny"
                                           else measured.DATA / "spot.obj")
        oracle = oracle_corrected(degraded, G, height_field)
        scans_info[obj] = {"scan": normal_error(degraded), f"oracle_h{G}": normal_error(oracle)}
        print(obj, json.dumps(scans_info[obj]), flush=True)
        for name in names:
            truth = common.heldout_table(name)
            B = common.default_basis_without(name)
            for seed in range(args.seeds):
                here, fitted = _height_runs(obj, name, seed, B, truth, degraded, oracle, G)
                for key, arrays in fitted.items():
                    scans_info[obj].setdefault(key, {})[f"{name}/{seed}"] = normal_error(arrays)
                rows.extend(here)
                print(f"{obj} {name} seed {seed}: " + ", ".join(
                    f"{r['scan']} {r['sphere']:.3f}" for r in here), flush=True)
    doc = {"machine": common.machine_end(info), "materials": names,
           "seeds": list(range(args.seeds)), "grid": G, "smoothness": HEIGHT_SMOOTHNESS,
           "iterations": HEIGHT_ITERATIONS, "field": "height",
           "settings": "Balanced (PipelineSettings() defaults), 3 photos, 1 % noise",
           "minutes": (time.perf_counter() - t_start) / 60.0,
           "normals": scans_info, "summary": summary(rows, objects), "runs": rows}
    path = common.RESULTS / ("normal_correction_height_quick.json" if args.quick
                             else "normal_correction_height.json")
    common.write_json(path, doc, arguments=dict(vars(args), field="height"))
    plot(doc, path.with_suffix(".png"))
    print(json.dumps(doc["summary"], indent=1))
    print(f"-> {path}")
    return 0


def _height_runs(obj, name, seed, B, truth, degraded, oracle, G):
    """One material and seed of ``--field height``: (the rows of Balanced on the scan, the
    oracle, the true-BRDF fit and the two rounds, the photo-fitted captures by name)."""
    photos = capture_arrays.photo_inputs(degraded, truth, noise=0.01, seed=seed)
    rows = []

    def balanced(scan, arrays, inputs=None):
        if inputs is None:  # the same photos (seed) with this scan's G-buffers
            inputs = capture_arrays.photo_inputs(arrays, truth, noise=0.01, seed=seed)
        row, table = _balanced_row(obj, name, seed, scan, B, arrays, inputs, truth)
        rows.append(row)
        return table

    own = balanced("scan", degraded, photos)
    balanced(f"oracle_h{G}", oracle)
    t0 = time.perf_counter()
    fitted = {f"alternated_h{G}": photo_fitted(degraded, photos, own, G, height_field)}
    fit_s = time.perf_counter() - t0
    fitted[f"photo_fit_h{G}"] = photo_fitted(degraded, photos, truth, G, height_field)
    balanced(f"photo_fit_h{G}", fitted[f"photo_fit_h{G}"])
    second = balanced(f"alternated_h{G}", fitted[f"alternated_h{G}"])
    fitted[f"alternated2_h{G}"] = photo_fitted(degraded, photos, second, G, height_field)
    balanced(f"alternated2_h{G}", fitted[f"alternated2_h{G}"])
    for row in rows:
        row["fit_s"] = fit_s  # one photo fit's seconds (the first round's)
    return rows, fitted


def _balanced_row(obj, name, seed, scan, B, arrays, inputs, truth):
    """One Balanced run on ``arrays``' scan: (its row of scores, its table)."""
    t0 = time.perf_counter()
    region = pipeline.run(B, inputs, pipeline.PipelineSettings(seed=seed),
                          regions=[0]).regions[0]
    seconds = time.perf_counter() - t0
    scores = photo_bench._scores(region.table, truth, arrays, inputs, region.reliable_pixels)
    row = {"object": obj, "material": name, "measured": common.is_measured(name),
           "seed": seed, "scan": scan, "sphere": scores["sphere"],
           "self_consistency": scores["self_consistency"], "energy": scores["energy"],
           "seconds": seconds}
    return row, region.table


def summary(rows, objects) -> dict:
    """Per object and scan: medians over the materials, and how many the scan's
    correction made better or worse than the uncorrected scan (by 10 % or more)."""
    out = {}
    for obj in objects:
        out[obj] = {}
        base = {r["material"]: r["sphere"] for r in rows
                if r["object"] == obj and r["scan"] == "scan" and r["seed"] == 0}
        for scan in dict.fromkeys(r["scan"] for r in rows if r["object"] == obj):
            sel = [r for r in rows if r["object"] == obj and r["scan"] == scan]
            here = {r["material"]: r["sphere"] for r in sel if r["seed"] == 0}
            out[obj][scan] = {
                "sphere": float(np.median([r["sphere"] for r in sel])),
                "self_consistency": float(np.median([r["self_consistency"] for r in sel])),
                "energy_min": float(min(r["energy"] for r in sel)),
                "sphere_photo_fit_materials": _median([v for m, v in here.items()
                                                       if m in PHOTO_FIT]),
                "better": sum(here[m] < 0.9 * base[m] for m in here),
                "worse": sum(here[m] > 1.1 * base[m] for m in here),
                "materials": len(here)}
    return out


def _median(values):
    return float(np.median(values)) if values else None


def _median_deg(entry: dict) -> float:
    """A scan's median normal error, or the median over materials for photo_fit_16."""
    if "median_deg" in entry:
        return entry["median_deg"]
    return float(np.median([e["median_deg"] for e in entry.values()]))


def plot(doc: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objects = list(doc["summary"])
    fig, axes = plt.subplots(1, len(objects), figsize=(6 * len(objects), 4.5), squeeze=False)
    for ax, obj in zip(axes[0], objects, strict=True):
        scans = list(doc["summary"][obj])
        runs = [r for r in doc["runs"] if r["object"] == obj]
        counts = {s: len({r["material"] for r in runs if r["scan"] == s}) for s in scans}
        labels = [f"{s.replace('_', ' ')}\n{_median_deg(doc['normals'][obj][s]):.1f} deg"
                  f"\n{counts[s]} materials" for s in scans]
        common.log_boxplot(
            ax, [[r["sphere"] for r in runs if r["scan"] == s] for s in scans], labels,
            "rendered-sphere error, Balanced (every material)",
            f"{obj}: scan normals corrected by smooth fields (truth- or photo-fitted)",
            label_size=7)
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
