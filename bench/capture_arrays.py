"""The bunny capture as arrays, for benchmarks that run the pipeline many times.

A capture (``testkit/capture.py``) is files: photos rendered by Cycles with the
ground-truth table. A sweep over settings and materials needs the same capture
hundreds of times, so this module keeps what does not change:

- :func:`gbuffers`: Cycles G-buffers (``brdf_addon.gbuffer``) of the ground-truth
  bunny and of its degraded "photogrammetry" copy, seen by the lit cameras of
  the capture's COLMAP ring, cached in ``<cache>/captures/arrays_<key>.npz``.
- :func:`photo_inputs`: photos of any table shaded with numpy on the ground
  truth's G-buffers (``selection.shade_gbuffer``: ``rho(n, l, v) (n.l) E V``, the
  same direct-light model the Cycles table shader renders; they agree within
  1 % on unshadowed pixels, ``tests/blender/test_table_shader.py``), paired with
  the scan's G-buffers as ``pipeline.PhotoInput``s, exactly what the extension
  hands to ``core.method.pipeline``.

One difference from the Cycles photos: the numpy photo holds the radiance at
the pixel centre, a Cycles photo the pixel's average (anti-aliasing). The demo
and the end-to-end tests use Cycles photos; sweeps use these.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import tempfile
import time

import numpy as np

# The capture's distant light (world space, towards the light), as in capture.generate.
LIGHT = (0.35, -0.45, 0.82)
FIELDS = ("truth_normal", "truth_position", "truth_visibility", "truth_mask",
          "scan_normal", "scan_position", "scan_visibility", "scan_region", "camera_center")


def _key(**options) -> str:
    text = json.dumps(options, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def gbuffers(resolution=(240, 180), n_views: int = 6, lit_views=(0, 2, 4), light=LIGHT,
             seed: int = 0, scan_options: dict | None = None, mesh=None,
             cache: bool = True, uv: bool = False) -> dict:
    """G-buffers of the truth and the scan for each lit camera, (V, H, W, ...) arrays.

    Returns a dict: ``truth_normal``, ``truth_position``, ``scan_normal``,
    ``scan_position`` (V, H, W, 3) float32 world space (unit normals, scene units;
    the object has unit radius); ``truth_visibility``, ``scan_visibility``
    (V, H, W) float32 in [0, 1]; ``truth_mask`` (V, H, W) bool; ``scan_region``
    (V, H, W) int32 (-1 = background); ``camera_center`` (V, 3) float64;
    ``scan_gbuffer_s``: Cycles seconds per photo for the scan's G-buffers (what
    a user's run costs; measured when rendered, stored in the cache);
    ``light`` (3,) unit; ``normal_error_deg`` (median, 90th percentile) of the
    scan's normals against the truth's over pixels both cover; ``render_s``
    wall seconds of the Cycles G-buffer renders (0 when read from the cache).
    uv: also ``truth_uv`` and ``scan_uv`` (V, H, W, 2) float32, the meshes' UV map
    (the scan keeps the truth's through the decimation; NaN on background), for
    textured captures (the mesh needs a UV map: Spot has one, the bunny none).
    Resets Blender to an empty scene when it has to render.
    """
    from brdf_reconstruct.core.brdf import basis
    from testkit import capture

    light = np.asarray(light, dtype=np.float64) / np.linalg.norm(light)
    mesh = pathlib.Path(mesh) if mesh else None
    key = _key(resolution=list(resolution), n_views=n_views, lit_views=list(lit_views),
               light=light.round(9).tolist(), seed=seed, scan_options=scan_options or {},
               mesh=mesh.name if mesh else {"bunny": "stanford-bunny.obj"}.get(
                   capture.default_subject(), "suzanne"), version=2,
               **({"uv": True} if uv else {}))
    path = basis.default_cache_dir() / "captures" / f"arrays_{key}.npz"
    if cache and path.is_file():
        with np.load(path) as data:
            out = {k: data[k] for k in data.files}
        out["render_s"] = 0.0
        return out
    out = _render(resolution, n_views, lit_views, light, seed, scan_options, mesh, uv)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        # a name of this process's own: two benches rendering the same capture at once
        # each write their copy and the last rename wins (the same arrays)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez_compressed(tmp, **{k: v for k, v in out.items() if k != "render_s"})
        tmp.replace(path)
    return out


def ambient_shading(resolution=(240, 180), n_views: int = 6, lit_views=(0, 2, 4),
                    seed: int = 0, scan_options: dict | None = None, mesh=None,
                    samples: int = 64, cache: bool = True) -> np.ndarray:
    """(V, H, W) float32: the ground truth seen by each lit camera of :func:`gbuffers`
    (the same arguments), as a white Lambertian surface (albedo 1) under a uniform
    white sky of radiance 1, rendered by Cycles (``samples`` per pixel, direct light
    and one bounce): 1 where a point sees the whole sky, less where the object
    occludes it (ambient occlusion, lit a little by the bounce); 0 on the
    background. What a photogrammetry texture baked from ambient photos holds
    besides the albedo (``bench/texture_bench.py``'s scan texture). Cached as
    :func:`gbuffers` is. Resets Blender to an empty scene when it has to render."""
    from brdf_reconstruct.core.brdf import basis
    from testkit import capture

    mesh = pathlib.Path(mesh) if mesh else None
    key = _key(kind="ambient", resolution=list(resolution), n_views=n_views,
               lit_views=list(lit_views), seed=seed, scan_options=scan_options or {},
               mesh=mesh.name if mesh else capture.default_subject(), samples=samples)
    path = basis.default_cache_dir() / "captures" / f"ambient_{key}.npy"
    if cache and path.is_file():
        return np.load(path)
    out = _render_ambient(resolution, n_views, lit_views, seed, scan_options, mesh, samples)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
        np.save(tmp, out)
        tmp.replace(path)
    return out


def _render_ambient(resolution, n_views, lit_views, seed, scan_options, mesh, samples):
    import bpy
    import OpenImageIO as oiio

    from brdf_reconstruct.brdf_addon import colmap_import
    from brdf_reconstruct.brdf_addon.scratch_scene import configure_cycles

    truth, scan, cameras = build_scene(resolution, n_views, seed, scan_options, mesh)
    scene = bpy.context.scene
    scan.hide_render = True
    material = bpy.data.materials.new("white diffuse")
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
    truth.data.materials.clear()
    truth.data.materials.append(material)
    world = bpy.data.worlds.new("white sky")
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    configure_cycles(scene, samples, bounces=1, seed=seed)
    r = scene.render
    r.film_transparent = True
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_mode = "RGBA"
    r.image_settings.color_depth = "32"
    views = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in lit_views:
            scene.camera = cameras[i]
            colmap_import.set_render_to_camera(scene, cameras[i])
            r.resolution_x, r.resolution_y = (int(v) for v in resolution)
            r.resolution_percentage = 100
            r.filepath = str(pathlib.Path(tmp) / f"ambient{i}.exr")
            bpy.ops.render.render(write_still=True)
            pixels = oiio.ImageBuf(r.filepath).get_pixels(oiio.FLOAT)
            views.append(np.where(pixels[..., 3] > 0.5, pixels[..., 0], 0.0))
    return np.stack(views).astype(np.float32)


def build_scene(resolution=(240, 180), n_views: int = 6, seed: int = 0,
                scan_options: dict | None = None, mesh=None):
    """``capture.build_scene`` with its COLMAP model in a temporary folder:
    ``(truth, scan, cameras)``; the same arguments give the same scan as
    :func:`gbuffers` rendered."""
    from testkit import capture

    with tempfile.TemporaryDirectory() as tmp:  # one point at the origin: the model the
        # cached arrays and bench/results were rendered with
        return capture.build_scene(pathlib.Path(tmp) / "sparse", resolution, n_views, seed,
                                   scan_options, mesh, points=np.zeros((1, 3)))


def _render(resolution, n_views, lit_views, light, seed, scan_options, mesh, uv=False) -> dict:
    from brdf_reconstruct.brdf_addon import gbuffer

    t0 = time.perf_counter()
    truth, scan, cameras = build_scene(resolution, n_views, seed, scan_options, mesh)
    scan_s = 0.0
    fields = FIELDS + (("truth_uv", "scan_uv") if uv else ())
    parts = {name: [] for name in fields}
    for i in lit_views:
        a = gbuffer.render_gbuffers(truth, cameras[i], light, resolution=tuple(resolution),
                                    uv=uv)
        t1 = time.perf_counter()
        b = gbuffer.render_gbuffers(scan, cameras[i], light, resolution=tuple(resolution),
                                    uv=uv)
        scan_s += time.perf_counter() - t1
        if uv:
            parts["truth_uv"].append(a.uv)
            parts["scan_uv"].append(b.uv)
        for name, value in (("truth_normal", a.normal), ("truth_position", a.position),
                            ("truth_visibility", a.visibility), ("truth_mask", a.mask),
                            ("scan_normal", b.normal), ("scan_position", b.position),
                            ("scan_visibility", b.visibility), ("scan_region", b.region),
                            ("camera_center", b.camera_center)):
            parts[name].append(value)
    out = {name: np.stack(value) for name, value in parts.items()}
    for name in fields:
        if out[name].dtype == np.float64 and name != "camera_center":
            out[name] = out[name].astype(np.float32)
    both = out["truth_mask"] & (out["scan_region"] >= 0)
    cos = np.clip(np.sum(out["truth_normal"][both] * out["scan_normal"][both], axis=-1,
                         dtype=np.float64), -1.0, 1.0)
    angles = np.degrees(np.arccos(cos))
    out["normal_error_deg"] = np.array([np.median(angles), np.percentile(angles, 90)])
    out["light"] = light
    out["render_s"] = time.perf_counter() - t0
    out["scan_gbuffer_s"] = np.array(scan_s / len(lit_views))
    return out


def photo_inputs(arrays: dict, table: np.ndarray, *, irradiance=1.0, noise: float = 0.0,
                 clip_level: float | None = None, seed: int = 0, views=None) -> list:
    """Photos of ``table`` on the ground truth's geometry, with the scan's G-buffers.

    table: (3, 90, 90, 180) ground-truth BRDF, 1/sr. noise: relative Gaussian
    noise per pixel and channel (0.01 = 1 %), seeded. clip_level: the camera's
    white level; pixels are clipped to it as a sensor saturates (the pipeline's
    ``ObservationSettings.clip_level`` decides what it then removes). views: the
    lit-view indices to use (default all). Returns ``pipeline.PhotoInput``s.
    """
    from brdf_reconstruct.core.method import pipeline, selection

    light = np.asarray(arrays["light"], dtype=np.float64)
    rng = np.random.default_rng(seed)
    inputs = []
    for i in range(len(arrays["camera_center"])) if views is None else views:
        f64 = {k: np.asarray(arrays[k][i], dtype=np.float64) for k in (
            "truth_normal", "truth_position", "truth_visibility", "scan_normal",
            "scan_position", "scan_visibility")}
        photo = selection.shade_gbuffer(table, f64["truth_normal"], f64["truth_visibility"],
                                        arrays["truth_mask"][i], f64["truth_position"],
                                        arrays["camera_center"][i], light, irradiance)
        if noise > 0.0:
            photo *= 1.0 + noise * rng.standard_normal(photo.shape)
            np.maximum(photo, 0.0, out=photo)
        if clip_level is not None:
            np.minimum(photo, clip_level, out=photo)
        inputs.append(pipeline.PhotoInput(
            photo=photo, normal=f64["scan_normal"], position=f64["scan_position"],
            visibility=f64["scan_visibility"], region=arrays["scan_region"][i],
            camera_center=arrays["camera_center"][i], light=light, irradiance=irradiance,
            name=f"view{i}"))
    return inputs


def textured_photo_inputs(arrays: dict, colour: np.ndarray, rest: np.ndarray,
                          texture: np.ndarray, shape, *, irradiance=1.0, noise: float = 0.0,
                          seed: int = 0, texel_uv: str = "truth") -> list:
    """Photos of a textured material on the ground truth's geometry, with the scan's
    G-buffers and UV map (``gbuffers(uv=True)``).

    The photo is ``rest`` shaded plus, per pixel, the texel's relative albedo
    (``texture``: (height * width, 3), ``shape`` = (height, width)) times ``colour``
    shaded (the part of the table the texture scales;
    ``testkit.synthetic.colour_tables``). texel_uv: which UV map gives a pixel its
    texel: "truth" (the texture lies on the true surface; the scan's UVs,
    interpolated through the decimation, misregister it) or "scan" (the texture is
    the scan's own, as photogrammetry bakes the photos onto the scan: a pixel's
    texel is the scan's UV at that pixel). Otherwise as :func:`photo_inputs`."""
    if texel_uv not in ("truth", "scan"):
        raise ValueError(f"texel_uv must be 'truth' or 'scan', got {texel_uv!r}")
    import dataclasses

    from brdf_reconstruct.core.method import albedo

    base = photo_inputs(arrays, rest, irradiance=irradiance)
    coloured = photo_inputs(arrays, colour, irradiance=irradiance)
    rng = np.random.default_rng(seed)
    out = []
    for i, (b, c) in enumerate(zip(base, coloured, strict=True)):
        uv = np.asarray(arrays[f"{texel_uv}_uv"][i], dtype=np.float64)
        texel = albedo.texel_index(uv.reshape(-1, 2), shape).reshape(uv.shape[:2])
        scale = np.where((texel >= 0)[..., None], texture[np.maximum(texel, 0)], 1.0)
        photo = b.photo + scale * c.photo
        if noise > 0.0:
            photo *= 1.0 + noise * rng.standard_normal(photo.shape)
            np.maximum(photo, 0.0, out=photo)
        out.append(dataclasses.replace(b, photo=photo, uv=np.asarray(arrays["scan_uv"][i],
                                                                     dtype=np.float64)))
    return out

