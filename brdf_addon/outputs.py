"""The run's outputs, written back (main thread, bpy): ``brdf_<region>.binary``,
the pictures and ``report.json`` in the output folder, one NEW material per region
(node group "BRDF Reconstruction") with its bake error, and
``scene.brdf.results``. Nothing of the user's is modified: new materials are
created (never assigned or edited in place) and outputs go to new files.
"""


from __future__ import annotations

import json
import os
import pathlib
import time

import bpy
import numpy as np

from ..core import files
from ..core.brdf import merl
from ..core.method import pictures, pipeline, selection
from . import gathering, prefs, props

# Lights for the bake error, camera space (+z to the viewer): not the fit's own
# error lights (core.bake.fitting.ERROR_LIGHTS); the fit itself sees no light.
BAKE_LIGHTS = np.array([[0.3, 0.2, 0.93], [-0.5, 0.4, 0.77]])


def output_path(scene) -> pathlib.Path:
    """The run's output folder, absolute (Blender's ``//`` resolved); not created.

    ValueError (one sentence) when it would not be absolute: ``//`` in a .blend
    that was never saved, or a path without ``//`` that is not absolute, would
    resolve against the folder Blender was started from."""
    raw = scene.brdf.output_dir or "//brdf_out"
    path = bpy.path.abspath(raw)
    if not os.path.isabs(path):
        if raw.startswith("//") and not bpy.data.filepath:
            raise ValueError(f"the output folder {raw} is relative to the .blend, which is "
                             "not saved: save the .blend first or set an absolute output "
                             "folder")
        raise ValueError(f"the output folder {raw} is relative to the folder Blender was "
                         "started from: start it with // for the .blend's folder or set "
                         "an absolute output folder")
    return pathlib.Path(path)


def output_dir(scene) -> pathlib.Path:
    """:func:`output_path`, created if missing and marked as a run's
    (``core.files.OUTPUT_MARKER``)."""
    path = output_path(scene)
    path.mkdir(parents=True, exist_ok=True)
    files.mark_output_folder(path)
    return path


def _as_image(name: str, picture: np.ndarray) -> bpy.types.Image:
    """A new Blender image holding a picture (row 0 = top; Blender stores bottom-up)."""
    h, w = picture.shape[:2]
    image = bpy.data.images.new(name, w, h, alpha=False)
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = picture[::-1]
    image.pixels.foreach_set(rgba.ravel())
    image.pack()
    return image


def write_back(scene, inputs, result: pipeline.PipelineResult, timings: dict,
               bake: bool = True, fits: dict | None = None,
               capture: dict | None = None, basis: dict | None = None,
               textured=None) -> dict:
    """Write tables, pictures, materials and ``report.json``; fill ``scene.brdf.results``.

    Returns the report dict. Existing files of the same name in the output
    folder are replaced (they are this tool's outputs); nothing else is.
    ``fits``: {region: (winner, LobeFit)} made beforehand off the main thread;
    a region whose winner changed since (Cycles selection) is fitted here.
    ``capture``: what was applied to the photos (``gather_capture``), reported.
    ``basis``: which PCA basis the run stood on (``prefs.load_planned``), reported.
    ``textured``: a textured run's ``core.method.textured.TexturedResult``: each
    region's texture is written beside its table (:func:`_write_texture`) and the
    material reads it.
    """
    settings = scene.brdf
    out = output_dir(scene)
    labels = gathering.region_labels(settings.target, settings.region_mode)
    settings.results.clear()
    settings.capture_notes = json.dumps(gathering.capture_notes(capture or {}))
    regions, for_gltf = [], []
    for r in result.regions:
        label = labels.get(r.region, f"region {r.region}")
        entry = settings.results.add()
        entry.region, entry.label, entry.status, entry.reason = (
            r.region, label, r.status, r.reason)
        entry.counts = json.dumps(r.counts)
        entry.notes = json.dumps(pipeline.region_notes(r.summary()))
        summary = r.summary() | {"label": label}
        if r.status == "ok":
            t0 = time.perf_counter()
            table_path = out / f"brdf_{r.region}.binary"
            merl.write(table_path, r.table)
            entry.table_path = str(table_path)
            entry.winner, entry.kl = r.winner, float(r.kl[r.winner])
            views = pipeline.region_views(inputs, r.region)
            picture = None
            if views:
                v = views[0]
                render = selection.shade_gbuffer(r.table, v.normal, v.visibility, v.mask,
                                                 v.position, v.camera_center, v.light,
                                                 v.irradiance)
                picture = pictures.photo_vs_render(v.photo, render, v.mask)
            slice_pic = pictures.slice_image(r.table)
            pictures.write_png(out / f"brdf_{r.region}_slice.png", slice_pic)
            entry.slice_plot = _as_image(f"BRDF {label} slice", slice_pic)
            summary["pictures"] = [f"brdf_{r.region}_slice.png"]
            if picture is not None:
                pictures.write_png(out / f"brdf_{r.region}_photo_vs_render.png", picture)
                summary["pictures"].append(f"brdf_{r.region}_photo_vs_render.png")
            if views and r.reliable_pixels is not None:
                first = int(r.observed_pixels[0, 0])  # the first photo seeing the region
                overlay = pictures.reliable_overlay(
                    inputs[first].photo, r.observed_pixels[r.observed_pixels[:, 0] == first, 1:],
                    r.reliable_pixels[r.reliable_pixels[:, 0] == first, 1:])
                name = f"brdf_{r.region}_reliable_region.png"
                pictures.write_png(out / name, overlay)
                summary["pictures"].append(name)
                entry.plot = _as_image(f"BRDF {label} photo vs render", picture)
            summary["table"] = table_path.name
            timings[f"outputs_region_{r.region}"] = time.perf_counter() - t0
            texture = None if textured is None else textured.textures.get(r.region)
            fit = (fits or {}).get(r.region)
            fit = fit[1] if fit is not None and fit[0] == r.winner else None
            if bake or texture is not None or settings.export_gltf:
                from ..core.bake import fitting

                fit = fit if fit is not None else fitting.fit(r.table)
            image = None
            if texture is not None:
                summary["texture"], image = _write_texture(out, r, texture, fit, label)
                image = (image, texture.model)
            for_gltf.append((r, label, fit, texture, image, summary))
            if bake:
                t0 = time.perf_counter()
                summary["material"] = _bake(scene, r, label, table_path, entry, fit, image)
                timings[f"bake_region_{r.region}"] = time.perf_counter() - t0
        regions.append(summary)
    gltf = _export_gltf(scene, out, for_gltf) if settings.export_gltf and for_gltf else None
    report = {
        "settings": props.settings_dict(settings),
        "scan": settings.target.name,
        "photos": result.photo_counts,
        "capture": capture or {},
        "basis": basis or {},
        "regions": regions,
        "timings_s": timings | {f"pipeline_{k}": v for k, v in result.timings.items()},
        "gltf": gltf,
        "cycles": {
            # the fewest each comparison needs, as measured (see docs/results.md)
            "gbuffers": {"samples": 1, "bounces": 0, "pixel_filter_px": 0.01,
                         "why": "one sample at the pixel center is exact geometry; "
                                "tests/blender/test_gbuffer.py"},
            "selection": {"path": settings.kl_path.lower(),
                          "samples": settings.kl_samples if settings.kl_path == "CYCLES"
                          else None, "bounces": 0,
                          "why": "bench/results/cycles_kl.json: the candidates' ranking "
                                 "is the same from 1 sample to 256"},
            "device": prefs.cycles_device(),
        },
        "blender": bpy.app.version_string,
    }
    files.write_text(out / "report.json", json.dumps(report, indent=1, default=_json_default))
    return report


def _write_texture(out: pathlib.Path, r, texture, fit, label: str):
    """Write a region's texture files; returns (report entry, the new Blender image
    of the albedo file, for the material). The albedo file's meaning follows the
    texture's model (``core.method.textured``): "diffuse": the diffuse colour per
    texel (the lobe fit's, times the texel's albedo over the region's), a 16-bit
    sRGB PNG; "whole": the multiplier of every colour (mean 1 over the measured
    texels), linear, an EXR (its values pass 1)."""
    from ..core.method import texture_io

    relative = texture.relative().reshape(*texture.map.shape, 3)
    if texture.model == "diffuse":
        name = f"brdf_{r.region}_albedo.png"
        clipped = texture_io.write_albedo(out / name, relative * fit.params.diffuse, "PNG")
        meaning = "diffuse color per texel (16-bit sRGB PNG)"
    else:
        name = f"brdf_{r.region}_albedo.exr"
        clipped = texture_io.write_albedo(out / name, relative, "EXR")
        meaning = "multiplier of every color of the material per texel (linear EXR)"
    coverage = f"brdf_{r.region}_coverage.png"
    texture_io.write_coverage(out / coverage, texture.map.coverage_image())
    image = bpy.data.images.load(str(out / name), check_existing=False)
    image.name = f"BRDF {label} albedo"
    image.colorspace_settings.name = "sRGB" if texture.model == "diffuse" else "Non-Color"
    entry = texture.summary() | {"albedo": name, "coverage": coverage, "meaning": meaning,
                                 "clipped_texels": clipped}
    return entry, image


def _bake(scene, r, label, table_path, entry, fit, image=None) -> dict:
    """Build the NEW material from the lobe fit, as the setting ``material_model``
    asks: the "BRDF Reconstruction" node group, or its Principled BSDF version
    (``core.bake.principled``); ``image`` = (the texture's Blender image, its model)
    goes in if given. The bake error (Cycles against the table, before the texture
    goes in: the shared shape's) is measured for both versions and reported; the
    one not chosen is built for that only and removed."""
    from . import material

    provenance = _provenance(scene, r, table_path)
    builders = {"NODE_GROUP": material.build_material,
                "PRINCIPLED": material.build_principled_material}
    chosen = scene.brdf.material_model
    errors, mat = {}, None
    for model, build in builders.items():
        made = build(f"BRDF {label}" if model == chosen else f"BRDF {label} (measured only)",
                     fit, provenance)
        errors[model.lower()] = material.bake_error(made, r.table, BAKE_LIGHTS)
        if model == chosen:
            mat = made
        else:
            bpy.data.materials.remove(made)
    out = {"name": mat.name, "model": chosen.lower(), "fit": json.loads(mat["brdf_fit"])
           if "brdf_fit" in mat else json.loads(mat["brdf_fit_source"]),
           "bake_error": errors[chosen.lower()], "bake_errors": errors}
    if "brdf_principled" in mat:
        out["principled"] = json.loads(mat["brdf_principled"])
    if image is not None:
        if not material.takes_texture(mat, image[1]):
            out["texture_applied"] = False
            out["texture_note"] = material.METAL_TEXTURE_NOTE
        else:
            material.add_texture(mat, image[0], scene.brdf.uv_map, image[1])
            out["texture_applied"] = True
    mat["brdf_bake_error"] = json.dumps(errors[chosen.lower()], default=_json_default)
    mat["brdf_bake_errors"] = json.dumps(errors, default=_json_default)
    entry.material = mat
    entry.bake_error = float(errors[chosen.lower()]["max"])
    return out


def _provenance(scene, r, table_path) -> dict:
    """What a new material records of the run that made it."""
    return {"table_path": str(table_path), "settings": props.settings_dict(scene.brdf),
            "region": int(r.region), "kl": float(r.kl[r.winner]), "trial": int(r.winner)}


def _export_gltf(scene, out: pathlib.Path, regions) -> dict:
    """``brdf_scan.glb`` (``gltf_export``): the scan wearing each reconstructed
    region's Principled BSDF version (whichever version its new material is), built
    for the export and removed after it. regions: (result, label, fit, texture,
    (albedo image, model) or None, the region's report entry) per region written.
    Returns the report's "gltf" entry; each region's entry gets its "gltf" part."""
    from . import gltf_export

    made, images, materials = [], [], {}
    try:
        for r, label, fit, texture, image, summary in regions:
            mat, extra, entry = gltf_export.region_material(
                f"BRDF {label} (glTF)", fit, _provenance(scene, r, out / summary["table"]),
                out, r.region, texture, None if image is None else image[0],
                scene.brdf.uv_map)
            made.append(mat)
            images += extra
            materials[r.region] = mat
            summary["gltf"] = entry
        return gltf_export.export_scan(scene, out / gltf_export.GLTF_NAME, materials)
    finally:
        for mat in made:
            bpy.data.materials.remove(mat)
        for image in images:
            bpy.data.images.remove(image)


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    return str(o)
