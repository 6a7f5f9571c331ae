"""Operators: one module per user action (a ``bpy.types.Operator`` each).

Modules: import_colmap (cameras from COLMAP), photos (add/remove lit photos),
light (the light of a photo), uv_copy (a UV map on a copy of the scan),
reconstruct (the whole run, modal), export. Each module
defines its operator classes, named like ``BRDF_OT_reconstruct`` with
``bl_idname = "brdf.reconstruct"``, and a ``CLASSES`` tuple; this package
concatenates those tuples here, and ``brdf_addon`` registers them. Operators
call ``core`` for the science.
"""

from . import export, import_colmap, light, photos, reconstruct, uv_copy

CLASSES = (import_colmap.CLASSES + photos.CLASSES + light.CLASSES + uv_copy.CLASSES
           + reconstruct.CLASSES + export.CLASSES)
