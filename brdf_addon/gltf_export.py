"""The scan as a glTF 2.0 binary wearing each region's Principled BSDF version
(issue 16): what other engines and tools read.

:func:`export_scan` writes ``brdf_scan.glb`` into the run's output folder through
Blender's own glTF exporter (``io_scene_gltf2``, shipped and enabled in Blender):

- the mesh is the scan as it renders (modifiers applied, in its world placement),
  made by ``Mesh.new_from_object`` into a new object of a temporary scene
  (:class:`ScratchScene`); the user's object, mesh, UV maps and materials are only
  read;
- the faces of each reconstructed region wear that region's material (built by
  :func:`region_material`); faces of a region that was not reconstructed keep the
  scan's own material;
- the file is written under a temporary name beside the destination and renamed
  into place when complete (``core.files.replacing``), so an error or Ctrl+C
  leaves no half-written ``.glb``.

The exporter maps a Principled BSDF to ``pbrMetallicRoughness`` (base colour,
metallic, roughness), ``KHR_materials_ior``/``specular``/``clearcoat``/``sheen``,
and an Image Texture linked straight to Base Color to ``baseColorTexture`` with
the mesh's UV map as ``TEXCOORD_0``.
"""

from __future__ import annotations

import json
import os
import pathlib

import bpy
import numpy as np

from ..core import files
from . import gbuffer, material
from .scratch_scene import ScratchScene

GLTF_NAME = "brdf_scan.glb"
_NAME = "BRDF_glTF"


def base_color_image(path: pathlib.Path, texture, base_color) -> tuple[bpy.types.Image, int]:
    """Write and load the per-texel base colour of a "whole"-model texture (the
    Principled base colour times the texel's multiplier, ``texture.relative()``),
    clipped to [0, 1] as glTF's sRGB texture must be: a 16-bit sRGB PNG at
    ``path``. Returns (the new Blender image, texels clipped)."""
    from ..core.method import texture_io

    relative = texture.relative().reshape(*texture.map.shape, 3)
    clipped = texture_io.write_albedo(path, relative * np.asarray(base_color[:3]), "PNG")
    image = bpy.data.images.load(str(path), check_existing=False)
    image.colorspace_settings.name = "sRGB"
    return image, clipped


def region_material(name: str, fit, provenance: dict, out: pathlib.Path, region: int,
                    texture=None, albedo_image=None, uv_map: str = "") -> tuple:
    """A NEW Principled BSDF material for the export of one region
    (:func:`material.build_principled_material` of the lobe fit) and its report
    entry. texture: the region's ``core.method.textured.RegionTexture`` or None;
    albedo_image: the Blender image of its albedo file (the "diffuse" model's
    diffuse colour per texel, which is a dielectric's base colour). A "whole"-model
    texture gets its own base-colour file, ``brdf_<region>_base_color.png`` in
    ``out``. Returns (material, images made for it, entry)."""
    mat = material.build_principled_material(name, fit, provenance)
    values = mat.node_tree.nodes[material.PRINCIPLED_NAME].inputs
    entry = {"material": mat.name, "principled": json.loads(mat["brdf_principled"])}
    images = []
    if texture is not None:
        if not material.takes_texture(mat, texture.model):
            entry["texture"] = None
            entry["texture_note"] = material.METAL_TEXTURE_NOTE
        else:
            if texture.model == "diffuse":
                image = albedo_image
            else:
                file = f"brdf_{region}_base_color.png"
                image, clipped = base_color_image(out / file, texture,
                                                  tuple(values["Base Color"].default_value))
                images.append(image)
                entry["base_color_file"], entry["clipped_texels"] = file, clipped
            material.add_texture(mat, image, uv_map, "diffuse")  # straight to Base Color
            entry["texture"] = os.path.basename(image.filepath)
    return mat, images, entry


def face_regions(mesh, mode: str = "MATERIAL_SLOT", n_slots: int = 0) -> np.ndarray:
    """(F,) int region id of each face of ``mesh``, as the G-buffers read it
    (``gbuffer.render_gbuffers``' region_attribute): the material index (indices
    past the last slot count as the last, as Blender renders them) or the sculpt
    face set (0 on a mesh without them)."""
    n = len(mesh.polygons)
    if mode == "FACE_SET":
        attribute = mesh.attributes.get(gbuffer.FACE_SET_ATTRIBUTE)
        ids = np.zeros(n, dtype=np.int32)
        if attribute is not None:
            attribute.data.foreach_get("value", ids)
        return ids
    ids = np.zeros(n, dtype=np.int32)
    mesh.polygons.foreach_get("material_index", ids)
    return np.clip(ids, 0, max(n_slots - 1, 0))


def export_scan(scene, path: pathlib.Path, materials: dict[int, bpy.types.Material]) -> dict:
    """Write ``path`` (a ``.glb``): the scan (``scene.brdf.target``) as it renders,
    the faces of region r wearing ``materials[r]``. Nothing of the user's scene is
    changed; everything made for the export is removed, also after an error.
    Returns the report entry (file name, faces per material, exporter version).
    RuntimeError (one sentence) when Blender's glTF exporter is missing."""
    if not hasattr(bpy.ops.export_scene, "gltf"):
        raise RuntimeError("Blender's glTF exporter (io_scene_gltf2) is not enabled, so "
                           "no .glb was written")
    settings = scene.brdf
    obj = settings.target
    depsgraph = bpy.context.evaluated_depsgraph_get()
    with ScratchScene(_NAME) as scratch:
        mesh = scratch.track(bpy.data.meshes, bpy.data.meshes.new_from_object(
            obj.evaluated_get(depsgraph), preserve_all_data_layers=True, depsgraph=depsgraph))
        own = [slot.material for slot in obj.material_slots]  # as the object shows them
        regions = face_regions(mesh, settings.region_mode, len(own))
        index = face_regions(mesh, "MATERIAL_SLOT", len(own))
        mesh.materials.clear()
        for m in own:
            mesh.materials.append(m)
        faces = {}
        for region, mat in sorted(materials.items()):
            mesh.materials.append(mat)
            chosen = regions == region
            index[chosen] = len(mesh.materials) - 1
            faces[mat.name] = int(chosen.sum())
        mesh.polygons.foreach_set("material_index", index)
        mesh.update()
        copy = scratch.new(bpy.data.objects, obj.name, mesh)
        copy.matrix_world = obj.matrix_world
        scratch.scene.collection.objects.link(copy)
        layer = scratch.scene.view_layers[0]
        with files.replacing(path) as tmp, bpy.context.temp_override(
                scene=scratch.scene, view_layer=layer):
            _run_exporter(tmp)
    version = next((".".join(map(str, mod.bl_info["version"]))
                    for mod in _addon_modules() if mod.__name__.endswith("io_scene_gltf2")),
                   None)
    return {"file": path.name, "faces": faces, "exporter": version}


def _run_exporter(tmp: pathlib.Path) -> None:
    """Blender's glTF exporter on the context scene, as a .glb at ``tmp``."""
    result = bpy.ops.export_scene.gltf(
        filepath=str(tmp), export_format="GLB", use_active_scene=True, export_apply=False,
        export_cameras=False, export_lights=False, export_materials="EXPORT",
        export_image_format="AUTO", export_yup=True, export_extras=False,
        export_animations=False)
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender's glTF exporter did not finish ({result})")


def _addon_modules():
    import addon_utils

    return addon_utils.modules()
