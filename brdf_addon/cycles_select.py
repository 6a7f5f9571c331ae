"""The accurate selection path: KL of Cycles renders against the photos.

The fast path (``core.method.selection``) shades each candidate *table* on the
G-buffers in numpy. This path renders the same table in Cycles, as the paper
does: a tabulated-BRDF material for the photo's light
(``brdf_addon.table_shader``), the scan rendered from each photo's camera under
that light, and the KL divergence of the region's pixel intensities against the
photo's (``core.method.kl``, same bins and floor as the fast path) scores it.

It used to render each candidate's baked lobe material instead
(``core.bake.fitting``), so the two paths ranked different BRDFs: on the bunny
capture the fast and Cycles rankings of the 16 Balanced trials correlated at a
median Spearman 0.58, while the fast KL of the baked candidates ranked as
Cycles did (0.94; ``bench/kl_agreement_bench.py``). The table is what is chosen
and written out; its bake, and the bake's own error, come after the choice.

Everything is built in a temporary scene: a copy of the scan object whose
material slots are object-linked to the candidate material (the user's mesh
and materials are untouched), the photo's camera, and a temporary Sun with
the photo's irradiance. Everything temporary is removed afterwards.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Vector

from ..core.capture import photo_io
from ..core.method import kl as kl_module
from ..core.method import pipeline, selection
from .scratch_scene import ScratchScene, configure_cycles, float_exr_output

_NAME = "BRDF_KL"


def render_candidate(obj, material, camera, light, irradiance, resolution, render_samples: int,
                     bounces: int = 0, device: str = "CPU", path=None) -> np.ndarray:
    """(H, W, 3) linear radiance: Cycles render of ``obj`` with ``material`` on every
    slot, seen by ``camera``, under a distant light (world direction ``light``,
    irradiance scalar or RGB W/m^2) in a :class:`ScratchScene`; ``path``: also keep
    the render there as a float EXR."""
    width, height = resolution
    irradiance = np.broadcast_to(np.asarray(irradiance, dtype=np.float64), (3,))
    with ScratchScene(_NAME) as scratch:
        scene = scratch.scene
        copy = scratch.track(bpy.data.objects, obj.copy())
        if not copy.material_slots:  # a slot needs the mesh: give the copy its own
            copy.data = scratch.track(bpy.data.meshes, obj.data.copy())
            copy.data.materials.append(material)
        for slot in copy.material_slots:  # object-linked: the user's mesh keeps its own
            slot.link = "OBJECT"
            slot.material = material
        scene.collection.objects.link(copy)
        scene.collection.objects.link(camera)
        scene.camera = camera
        sun_data = scratch.new(bpy.data.lights, _NAME, "SUN")
        peak = float(irradiance.max())
        sun_data.energy = peak
        sun_data.color = tuple(irradiance / peak)
        sun_data.angle = 0.0
        sun = scratch.new(bpy.data.objects, _NAME, sun_data)
        scene.collection.objects.link(sun)
        sun.rotation_mode = "QUATERNION"
        sun.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(Vector(tuple(light)))
        configure_cycles(scene, render_samples, device=device, bounces=bounces)
        r = scene.render
        r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
        ctx = bpy.context.scene.render
        r.pixel_aspect_x, r.pixel_aspect_y = ctx.pixel_aspect_x, ctx.pixel_aspect_y
        r.film_transparent = True
        float_exr_output(scene)
        return photo_io.read_photo(scratch.render(path if path is not None else "kl.exr"))


def score_candidate(scene, inputs, region: int, table, render_samples: int = 16,
                    n_bins: int = 64, bounces: int = 0, device: str = "CPU") -> np.ndarray:
    """(V,) KL per photo that sees ``region``, of Cycles renders of ``table`` (a
    temporary tabulated-BRDF material per light, ``table_shader.table_material``)
    against the photo, over the region's pixels. ``inputs``: the run's
    ``pipeline.PhotoInput`` list, in the order of ``scene.brdf.photos``."""
    from . import table_shader

    photos = list(scene.brdf.photos)
    seen = [i for i, p in enumerate(inputs) if np.any(np.asarray(p.region) == region)]
    views = pipeline.region_views(inputs, region)
    if not views:
        raise ValueError(f"region {region}: no photo sees it")
    made = {}  # light direction -> material: photos under one light share it
    try:
        kl = np.zeros(len(views))
        for j, (i, v) in enumerate(zip(seen, views, strict=True)):
            key = tuple(np.round(np.asarray(v.light, dtype=np.float64), 12))
            if key not in made:
                made[key] = table_shader.table_material(f"{_NAME} candidate", table, v.light)
            h, w = v.mask.shape
            image = render_candidate(scene.brdf.target, made[key], photos[i].camera,
                                     v.light, v.irradiance, (w, h), render_samples, bounces,
                                     device)
            ok = v.mask & np.all(np.isfinite(v.photo), axis=-1)
            # the fast path's bins: log-spaced over the photo's positive range, down to
            # selection.DYNAMIC_RANGE of its brightest value
            kl[j] = kl_module.kl_divergence(v.photo[ok], image[ok], n_bins=n_bins,
                                            range=selection.photo_range(v.photo[ok]))
        return kl
    finally:
        remove_materials(list(made.values()))


def select_by_cycles(scene, inputs, region: int, tables, render_samples: int = 16,
                     n_bins: int = 64, bounces: int = 0, device: str = "CPU"):
    """Score every candidate table of one region by Cycles renders; returns
    ``(kl (T,) mean over photos, winner)``."""
    score = np.array([score_candidate(scene, inputs, region, t, render_samples, n_bins, bounces,
                                      device).mean() for t in tables])
    return score, int(np.argmin(score))


def remove_materials(materials) -> None:
    """Delete candidate materials made by :func:`score_candidate`, with their node
    groups and table images once nothing else uses them."""
    for mat in materials:
        nodes = list(mat.node_tree.nodes)
        groups = [n.node_tree for n in nodes
                  if n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None]
        images = [n.image for n in nodes
                  if n.bl_idname == "ShaderNodeTexImage" and n.image is not None]
        bpy.data.materials.remove(mat)
        for g in groups:
            if g.users == 0:
                bpy.data.node_groups.remove(g)
        for image in images:
            if image.users == 0:
                bpy.data.images.remove(image)

