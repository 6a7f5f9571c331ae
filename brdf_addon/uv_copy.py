"""A UV map for a scan that has none, made on a copy (issue 16): the user's object
and mesh are never changed.

:func:`make_uv_copy` duplicates the scan (object and mesh; its materials shared, as
Blender's Duplicate does), gives the copy's mesh a UV map by Blender's Smart UV
Project, and links the copy into the scan's collections. The panel's *Make UV Map
on a Copy* (``brdf.uv_copy``, undoable) and a job's ``uv_on_copy = true`` call it;
both then make the copy the run's scan (``scene.brdf.target``).
"""

from __future__ import annotations

import math

import bpy

UV_NAME = "BRDF UV"
# Smart UV Project's own defaults (Blender 4.2-5.0), spelled out so a change of
# Blender's defaults does not change our maps silently
ANGLE_LIMIT_DEG = 66.0
ISLAND_MARGIN = 0.0


def make_uv_copy(scene, obj) -> bpy.types.Object:
    """A new object "<name> (UV)": a copy of mesh object ``obj`` with its own mesh
    copy, which gets a UV map ``UV_NAME`` (every face unwrapped by Smart UV Project,
    UVs in [0, 1]), linked into ``obj``'s collections (or ``scene``'s own). ``obj``
    and its mesh are only read; the context's active object and selection are put
    back. ValueError (one sentence) for an object that is not a mesh with faces, or
    one that already has a UV map."""
    if getattr(obj, "type", None) != "MESH" or len(obj.data.polygons) == 0:
        raise ValueError(f"the scan {getattr(obj, 'name', obj)} is not a mesh with faces, so "
                         "no UV map can be made for it")
    if len(obj.data.uv_layers):
        raise ValueError(f"the scan {obj.name!r} already has a UV map "
                         f"({obj.data.uv_layers[0].name!r}); no copy is needed")
    copy = obj.copy()
    copy.data = obj.data.copy()
    copy.name = f"{obj.name} (UV)"
    copy.data.name = f"{obj.data.name} (UV)"
    for collection in (obj.users_collection or (scene.collection,)):
        collection.objects.link(copy)
    try:
        copy.data.uv_layers.new(name=UV_NAME)
        _smart_project(scene, copy)
    except BaseException:
        mesh = copy.data
        bpy.data.objects.remove(copy)
        bpy.data.meshes.remove(mesh)
        raise
    return copy


def _smart_project(scene, obj) -> None:
    """Smart UV Project on every face of ``obj`` (edit mode for the operator, then
    object mode); the view layer's active object and selection are restored."""
    layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    active = layer.objects.active
    selected = [o for o in layer.objects if o.select_get(view_layer=layer)]
    try:
        for o in selected:
            o.select_set(False, view_layer=layer)
        obj.select_set(True, view_layer=layer)
        layer.objects.active = obj
        with bpy.context.temp_override(scene=scene, view_layer=layer, active_object=obj,
                                       object=obj, selected_objects=[obj],
                                       selected_editable_objects=[obj]):
            bpy.ops.object.mode_set(mode="EDIT")
            try:
                bpy.ops.mesh.select_all(action="SELECT")
                bpy.ops.uv.smart_project(angle_limit=math.radians(ANGLE_LIMIT_DEG),
                                         island_margin=ISLAND_MARGIN,
                                         scale_to_bounds=False)
            finally:
                bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        obj.select_set(False, view_layer=layer)
        for o in selected:
            o.select_set(True, view_layer=layer)
        layer.objects.active = active
