"""A textured result to look at (issue 16): photo, reconstruction and relit render
side by side, on Spot with a measured material under a patch texture.

    .venv/bin/python bench/texture_figure.py [--material NAME] [--seed S]

The capture is ``bench/texture_bench.py``'s Spot (three lit views of 240 x 180 under
``capture_arrays.LIGHT``, photos shaded from the true table times a 64 x 64 patch
texture of 10:1 or more, 1 % noise), the material held out of the basis
(``common.default_basis_without``), Balanced's settings, ``core.method.textured``.
Per scan ("exact": the truth's G-buffers; "degraded": the photogrammetry mesh),
one row of four pictures of view 0:

1. the input photo (light A, the capture's);
2. the reconstruction rendered on the scan under light A (the shared table, its
   diffuse part or whole times the texel's albedo, as the material renders it);
3. the reconstruction relit: rendered on the scan under light B, which no photo saw
   (``RELIGHT``; new Cycles G-buffers of the same views);
4. the true photo under light B, for comparison.

Numbers (relative RMSE over the object's pixels, and the albedo error of
``texture_bench.pattern_error``) go to ``bench/results/texture_figure.json``, the
picture to ``texture_figure.png``. About 4 minutes on the 2-core machine (the
G-buffers under light B are rendered once and cached).
"""

from __future__ import annotations

import argparse
import sys
import time

import capture_arrays
import common
import numpy as np
import texture_bench

from brdf_reconstruct.core.method import albedo, pipeline, selection, textured
from testkit import synthetic

RELIGHT = (0.6, 0.55, 0.58)  # light B: about 55 degrees from view 0, not seen by a photo
MATERIAL = "purple-paint"  # measured; its texture scales the whole table
VIEW = 0


def shade_textured(table, texture: textured.RegionTexture, p: pipeline.PhotoInput,
                   uv) -> np.ndarray:
    """(H, W, 3) radiance of a textured region as its material renders it: the
    table's colour part (``textured.colour_part`` with the texture's model) times the
    texel's relative albedo, plus the rest, shaded on ``p``'s G-buffers (direct light,
    ``selection.shade_gbuffer``). uv: (H, W, 2) the scan's UV map in that view."""
    t = np.asarray(table, dtype=np.float64)
    flat = t.reshape(3, -1).T
    d, s = textured.colour_part(flat, texture.delta, texture.cap)
    mask = np.asarray(p.region) >= 0

    def shade(part):
        return selection.shade_gbuffer(part.T.reshape(t.shape), p.normal, p.visibility, mask,
                                       p.position, p.camera_center, p.light, p.irradiance)

    texel = albedo.texel_index(np.asarray(uv, dtype=np.float64).reshape(-1, 2),
                               texture.map.shape).reshape(np.shape(uv)[:2])
    scale = np.where((texel >= 0)[..., None], texture.relative()[np.maximum(texel, 0)], 1.0)
    return shade(s) + scale * shade(d)


def relative_rmse(estimate, truth, mask) -> float:
    e, t = estimate[mask], truth[mask]
    return float(np.sqrt(np.mean((e - t) ** 2)) / max(np.sqrt(np.mean(t ** 2)), 1e-12))


def one_scan(name: str, scan: str, arrays_a: dict, arrays_b: dict, seed: int) -> dict:
    """The reconstruction from the photos under light A, and the four pictures."""
    shape = texture_bench.SPOT_SHAPE
    colour, rest, kind = texture_bench.truth_parts(name)
    tex = synthetic.patch_texture(shape, patch=8, seed=seed)
    photos = capture_arrays.textured_photo_inputs(arrays_a, colour, rest, tex, shape,
                                                  noise=0.01, seed=seed)
    basis = common.default_basis_without(name)
    t0 = time.perf_counter()
    result = textured.run(basis, photos, pipeline.PipelineSettings(seed=seed,
                                                                   **texture_bench.SETTINGS),
                          textured.TextureSettings(shape=shape))
    seconds = time.perf_counter() - t0
    table, texture = result.result.regions[0].table, result.textures[0]
    truth_b = capture_arrays.textured_photo_inputs(arrays_b, colour, rest, tex, shape)
    p_a, p_b = photos[VIEW], truth_b[VIEW]
    render_a = shade_textured(table, texture, p_a, arrays_a["scan_uv"][VIEW])
    render_b = shade_textured(table, texture, p_b, arrays_b["scan_uv"][VIEW])
    mask_a = np.asarray(arrays_a["truth_mask"][VIEW]) & (np.asarray(p_a.region) >= 0)
    mask_b = np.asarray(arrays_b["truth_mask"][VIEW]) & (np.asarray(p_b.region) >= 0)
    return {
        "scan": scan, "truth": kind, "model": texture.model,
        "constant": bool(texture.map.constant),
        "albedo_error": texture_bench.pattern_error(texture, tex),
        "photo_error_light_a": relative_rmse(render_a, p_a.photo, mask_a),
        "relit_error_light_b": relative_rmse(render_b, p_b.photo, mask_b),
        "seconds_textured": seconds,
        "_pictures": (p_a.photo, render_a, render_b, p_b.photo),
    }


def plot(rows: list, name: str, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = ("photo (light A)", "reconstruction (light A)", "relit (light B, unseen)",
              "true photo (light B)")
    fig, axes = plt.subplots(len(rows), 4, figsize=(12, 2.6 * len(rows)), squeeze=False)
    for row, r in zip(axes, rows, strict=True):
        pictures = r["_pictures"]
        white = max(float(np.percentile(pictures[0], 99.5)), 1e-6)  # one exposure per row
        for k, (ax, picture) in enumerate(zip(row, pictures, strict=True)):
            srgb = np.clip(picture / white, 0.0, 1.0) ** (1 / 2.2)
            ax.imshow(srgb)
            ax.set_xticks([])
            ax.set_yticks([])
            if k == 1:
                ax.set_xlabel(f"rel. RMSE {r['photo_error_light_a']:.3f}")
            if k == 2:
                ax.set_xlabel(f"rel. RMSE {r['relit_error_light_b']:.3f}")
            if row is axes[0]:
                ax.set_title(titles[k], fontsize=10)
        row[0].set_ylabel(f"{r['scan']} scan\nalbedo err {r['albedo_error']:.3f}")
    fig.suptitle(f"Textured Spot, {name} (held out of the basis) x a 64 x 64 patch texture; "
                 "Balanced", fontsize=11)
    fig.tight_layout()
    common.save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default=MATERIAL)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    info = common.machine()
    t0 = time.perf_counter()
    spot = texture_bench.spot_arrays()
    light_b = np.asarray(RELIGHT) / np.linalg.norm(RELIGHT)
    relit = texture_bench.spot_arrays(light_b)
    rows = []
    for scan, label in (("exact", "exact"), ("blunted", "degraded")):
        r = one_scan(args.material, label, spot[scan], relit[scan], args.seed)
        print(f"{label}: albedo {r['albedo_error']:.3f}, photo {r['photo_error_light_a']:.3f}, "
              f"relit {r['relit_error_light_b']:.3f} ({r['seconds_textured']:.0f} s)",
              flush=True)
        rows.append(r)
    plot(rows, args.material, common.RESULTS / "texture_figure.png")
    doc = {"machine": common.machine_end(info), "minutes": (time.perf_counter() - t0) / 60,
           "material": args.material, "seed": args.seed, "light_a": list(spot["exact"]["light"]),
           "light_b": light_b.tolist(), "view": VIEW, "settings": texture_bench.SETTINGS,
           "rows": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]}
    common.write_json(common.RESULTS / "texture_figure.json", doc, arguments=vars(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
