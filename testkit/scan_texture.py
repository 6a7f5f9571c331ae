"""The scan's own colour texture, as photogrammetry bakes it from ambient photos,
for the textured captures of the tests and benches (issue 16): not the albedo,
but its product with the ambient occlusion and the specular's reflection of the
sky, averaged over the views (``bench/texture_bench.py``'s prior).

Arrays of a capture (``arrays``), per view i: ``truth_normal`` / ``truth_position``
(H, W, 3) world, ``truth_mask`` (H, W) bool, ``camera_center`` (3,), ``truth_uv`` /
``scan_uv`` (H, W, 2) the truth's and the scan's UV maps, ``ambient`` (H, W) the
fraction of a uniform white sky each point sees."""

from __future__ import annotations

import numpy as np

from brdf_reconstruct.core.brdf import energy
from testkit import synthetic


def numpy_arrays(truth, seen) -> dict:
    """The numpy scene as ``scan_texture`` reads a capture: one view (its photos share
    the camera), the plane's (x, y) as both UV maps, the height field's sky."""
    uv = synthetic.height_field_uv(seen)[None]
    return {"truth_normal": truth.normal[None], "truth_position": truth.position[None],
            "truth_mask": truth.mask[None], "camera_center": truth.camera_center[None],
            "truth_uv": uv, "scan_uv": uv,
            "ambient": height_field_sky(truth.position[..., 2])[None]}


def height_field_sky(z: np.ndarray, directions: int = 16, reach: int = 48) -> np.ndarray:
    """(H, W) the fraction of a uniform sky (cosine-weighted, about the vertical) each
    point of the numpy scene's height field sees: 1 - the mean over ``directions``
    azimuths of sin^2 of the horizon's elevation within ``reach`` pixels (the scene
    spans [-1, 1]; beyond its edge the nearest height)."""
    res = z.shape[0]
    step = 2.0 / res
    pad = np.pad(z, reach, mode="edge")
    sin2 = np.zeros_like(z)
    for angle in np.arange(directions) * 2.0 * np.pi / directions:  # 16 azimuths
        tangent = np.zeros_like(z)
        for k in range(1, reach + 1):  # ... times 48 steps, each a whole-image shift
            di, dj = int(round(-k * np.sin(angle))), int(round(k * np.cos(angle)))
            other = pad[reach + di: reach + di + res, reach + dj: reach + dj + res]
            tangent = np.maximum(tangent, (other - z) / (np.hypot(di, dj) * step))
        sin2 += tangent**2 / (1.0 + tangent**2)
    return 1.0 - sin2 / directions


def scan_texture(arrays: dict, colour, rest, texture, shape, ambient, *,
                 registration: str = "truth", noise: float = 0.01, seed: int = 0) -> np.ndarray:
    """(height, width, 3) the scan's own colour texture, as photogrammetry bakes it:
    each lit camera's ambient photo of the truth (``ambient``: (V, H, W)
    ``capture_arrays.ambient_shading``, the sky each point sees) with the textured
    table's reflection of a uniform white sky towards that camera (the texel's
    albedo times ``colour``'s directional albedo plus ``rest``'s, at the angle
    between the true normal and the view), 1 % noise, projected through the
    scan's UVs and averaged over the views per texel (NaN where no view sees
    one). Not the albedo: the ambient occlusion, the specular's reflection of the
    sky and the misregistration of the scan's UVs (``registration="truth"``) are
    in it, as in a real scan's texture; an uneven sky and the photos' exposure
    are not."""
    from brdf_reconstruct.core.method import albedo as albedo_

    scaled = energy.directional_albedo(colour)  # (90, 3) at 0.5, 1.5, ... 89.5 degrees
    fixed = energy.directional_albedo(rest) if np.nanmax(rest) > 0.0 else np.zeros((90, 3))
    n_texels = shape[0] * shape[1]
    total, count = np.zeros((n_texels, 3)), np.zeros(n_texels)
    rng = np.random.default_rng(1000 + seed)
    for i in range(len(arrays["truth_normal"])):  # a loop over the 3 views
        seen = arrays["truth_mask"][i] & np.isfinite(arrays["scan_uv"][i]).all(axis=-1)
        n = arrays["truth_normal"][i][seen].astype(np.float64)
        v = arrays["camera_center"][i] - arrays["truth_position"][i][seen]
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        angle = np.clip(np.degrees(np.arccos(np.clip(np.sum(n * v, axis=1), 0.0, 1.0))),
                        0, 89).astype(int)
        on = albedo_.texel_index(arrays[f"{registration}_uv"][i][seen].reshape(-1, 2), shape)
        to = albedo_.texel_index(arrays["scan_uv"][i][seen].reshape(-1, 2), shape)
        a = np.where((on >= 0)[:, None], texture[np.maximum(on, 0)], 1.0)
        radiance = ambient[i][seen][:, None] * (a * scaled[angle] + fixed[angle])
        radiance *= 1.0 + noise * rng.standard_normal(radiance.shape)
        ok = to >= 0
        for c in range(3):
            total[:, c] += np.bincount(to[ok], radiance[ok, c], minlength=n_texels)
        count += np.bincount(to[ok], minlength=n_texels)
    out = np.full((n_texels, 3), np.nan)
    out[count > 0] = total[count > 0] / count[count > 0, None]
    return out.reshape(*shape, 3)
